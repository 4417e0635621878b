"""Layering rules: sim is a pure library; lower app layers never import higher ones."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

FORBIDDEN = {
    # package prefix -> modules it must never import
    "sim": ("app", "fastapi", "can", "cantools", "uvicorn", "starlette", "pandas"),
    "app/signals": ("app.ingest", "app.analysis", "app.pipeline", "app.api", "app.storage", "app.cli"),
    "app/ingest": ("app.analysis", "app.pipeline", "app.api", "app.cli"),
    "app/analysis": ("app.pipeline", "app.api", "app.cli", "fastapi", "app.identify.logs"),
    "app/identify/base.py": ("app.pipeline", "app.api", "app.cli", "fastapi", "app.analysis.diagnosis.select"),
    "app/identify/fit.py": ("app.pipeline", "app.api", "app.cli", "fastapi", "app.analysis.diagnosis.select"),
    "app/identify/modal.py": ("app.pipeline", "app.api", "app.cli", "fastapi", "app.analysis.diagnosis.select"),
    "app/identify/logs.py": ("app.api", "app.cli", "fastapi"),
    "app/storage": ("app.api", "app.cli", "fastapi"),
    "app/pipeline.py": ("app.api", "app.cli", "fastapi"),
}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
    return found


def _cases() -> list[tuple[str, Path]]:
    cases = []
    for prefix in FORBIDDEN:
        root = REPO / prefix
        files = [root] if root.suffix == ".py" else sorted(root.rglob("*.py"))
        cases.extend((prefix, f) for f in files if f.exists())
    return cases


@pytest.mark.parametrize(("prefix", "path"), _cases(), ids=lambda v: str(v))
def test_layering(prefix: str, path: Path) -> None:
    bad = sorted(
        mod for mod in _imports(path)
        for banned in FORBIDDEN[prefix]
        if mod == banned or mod.startswith(banned + ".")
    )
    assert not bad, f"{path.relative_to(REPO)} imports {bad}, which {prefix} must not depend on"
