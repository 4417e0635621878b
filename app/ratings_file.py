"""Rating models on disk: written by ``lashscope ratings fit``, applied to analyses (:mod:`app.analysis.ratings`).

A model is a JSON file (format, version = content hash, the fit, its cross-validated error). An
analysis applies one when it is named: ``lashscope analyze --ratings MODEL.json``, or for every
analysis of a process (the service, its job workers, the batch) the environment variable
``LASHSCOPE_RATINGS=MODEL.json``. Without one no score is computed or shown.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from app import atomic
from app.analysis.ratings import RatingModel
from app.errors import InputError, StorageError
from app.settings import Settings

ENV = "LASHSCOPE_RATINGS"


def load_model(path: str | os.PathLike[str]) -> RatingModel:
    """Read a model file; :class:`~app.errors.InputError` (``ratings_model``) when it is missing or not a model."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"rating model {p}: no such file", code="ratings_model") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"rating model {p}: cannot read ({exc})", code="ratings_model") from exc
    return RatingModel.from_dict(data, f"rating model {p}")


def save_model(model: RatingModel, path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_text(p, json.dumps(model.to_dict(), indent=1) + "\n")
    except OSError as exc:
        raise StorageError(f"rating model {p}: cannot write ({exc.strerror or exc})") from exc
    return p


def model_from_env() -> RatingModel | None:
    """The model ``LASHSCOPE_RATINGS`` names (``Settings.ratings``, read now), or None when it is unset."""
    value = Settings().ratings.strip()
    return load_model(value) if value else None
