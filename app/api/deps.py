"""Dependencies as ``Annotated`` aliases: routes declare ``store: StoreDep`` and so on."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from app.jobs import JobRunner
from app.settings import Settings, get_settings
from app.storage.base import Store
from app.storage.results import ResultCache


def get_store(request: Request) -> Store:
    store: Store = request.app.state.store
    return store


def get_runner(request: Request) -> JobRunner:
    runner: JobRunner = request.app.state.runner
    return runner


def get_results(request: Request) -> ResultCache:
    cache: ResultCache = request.app.state.results
    return cache


SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[Store, Depends(get_store)]
RunnerDep = Annotated[JobRunner, Depends(get_runner)]
ResultsDep = Annotated[ResultCache, Depends(get_results)]
