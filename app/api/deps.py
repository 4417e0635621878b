"""Dependencies as ``Annotated`` aliases: routes declare ``store: StoreDep`` and so on.

The app-state getters are ``async`` so resolving them never costs a thread-pool hop (a plain
``def`` dependency runs in the thread pool on every request). The settings too are the app's
own (``app.state.settings``, set by :func:`app.api.main.create_app`), not a dependency override:
with any override set, FastAPI rebuilds every dependency's signature on every request.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from app.jobs import JobRunner
from app.settings import Settings
from app.storage.base import Store
from app.storage.results import ResultCache


async def get_store(request: Request) -> Store:
    store: Store = request.app.state.store
    return store


async def get_runner(request: Request) -> JobRunner:
    runner: JobRunner = request.app.state.runner
    return runner


async def get_app_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


async def get_results(request: Request) -> ResultCache:
    cache: ResultCache = request.app.state.results
    return cache


SettingsDep = Annotated[Settings, Depends(get_app_settings)]
StoreDep = Annotated[Store, Depends(get_store)]
RunnerDep = Annotated[JobRunner, Depends(get_runner)]
ResultsDep = Annotated[ResultCache, Depends(get_results)]
