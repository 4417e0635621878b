"""Layering rules: sim is a pure library; lower app layers never import higher ones; no import cycles.

The layers, from the bottom (docs/architecture.md draws them): ``sim`` (pure library) | ``app.errors``, ``app.serial``,
``app.signals`` | ``app.ingest`` | ``app.identify`` and ``app.analysis`` (pure functions) | ``app.pipeline``
(the analysis chained; no side effects) | ``app.payload``, ``app.fleet``, ``app.storage``, ``app.jobkinds``
(what is stored and written, and who runs it) | ``app.api``, ``app.cli`` (the two front doors).
Imports inside functions count as much as those at the top; ``if TYPE_CHECKING:`` blocks count for the layering,
not for cycles (they do not run).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

FORBIDDEN = {
    # package prefix -> modules it must never import
    "sim": ("app", "fastapi", "can", "cantools", "uvicorn", "starlette", "pandas"),
    "app/signals": ("app.ingest", "app.analysis", "app.pipeline", "app.api", "app.storage", "app.cli"),
    # and not the simulator: a process that only reads a log would load numba (bench/ingest.py's whole-process ratio)
    "app/ingest": ("app.analysis", "app.pipeline", "app.api", "app.cli", "sim"),
    "app/analysis": ("app.pipeline", "app.api", "app.cli", "fastapi", "app.identify.logs"),
    "app/identify/base.py": ("app.pipeline", "app.api", "app.cli", "fastapi", "app.analysis.diagnosis.select"),
    "app/identify/fit.py": ("app.pipeline", "app.api", "app.cli", "fastapi", "app.analysis.diagnosis.select"),
    "app/identify/modal.py": ("app.pipeline", "app.api", "app.cli", "fastapi", "app.analysis.diagnosis.select"),
    "app/identify/logs.py": ("app.api", "app.cli", "fastapi"),
    "app/storage": ("app.api", "app.cli", "fastapi", "app.jobkinds"),
    # the server reads and writes job artefacts through store.artifacts; a kind's module loads in its worker
    "app/api": ("app.jobkinds.diagnosis", "app.jobkinds.validation", "app.jobkinds.identification",
                "app.jobkinds.batch", "app.jobkinds.tolerance", "app.jobkinds.analysis"),
    "app/pipeline.py": ("app.api", "app.cli", "fastapi", "app.fleet", "app.payload", "app.storage", "app.jobkinds"),
}

# what app.analysis may import from the project: itself, the layers below it and the simulator
ANALYSIS_MAY_IMPORT = ("app.analysis", "app.errors", "app.progress", "app.serial", "app.signals", "app.identify", "sim")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for pkg in ("app", "sim") for p in sorted((REPO / pkg).rglob("*.py"))}


def _import_nodes(tree: ast.AST, typing: bool) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement, at the top or inside functions; those under ``if TYPE_CHECKING:`` only with
    ``typing`` (a layer must not name a higher one even for types; a cycle needs imports that run)."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import | ast.ImportFrom):
                found.append(child)
            elif not typing and isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                for stmt in child.orelse:
                    visit(stmt)
            else:
                visit(child)

    visit(tree)
    return found


def _imports(path: Path, typing: bool = True) -> set[str]:
    """Absolute names of what ``path`` imports: ``from a.b import c`` gives ``a.b`` and, when it is a module
    of the project, ``a.b.c``; relative imports are resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    name = _module_name(path) if path.is_relative_to(REPO) else ""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in _import_nodes(tree, typing):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
            continue
        base = node.module or ""
        if node.level:
            up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
            base = ".".join(up + ([node.module] if node.module else []))
        submodules = {f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in MODULES}
        found.update(submodules)
        if len(submodules) < len(node.names):
            found.add(base)
    return found


def _project_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (a name resolved to the longest module it names)."""
    def resolve(name: str) -> str | None:
        while name and name not in MODULES:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for mod, path in MODULES.items():
        targets = {resolve(n) for n in _imports(path, typing=False)}
        graph[mod] = {t for t in targets if t is not None and t != mod}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return cycles


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



def test_no_import_cycles_among_project_modules() -> None:
    cycles = import_cycles(_project_graph())
    assert cycles == [], "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_cycle_finder_finds_a_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert import_cycles(graph) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_in_function_and_type_checking_imports_are_seen() -> None:
    mod = REPO / "app" / "fleet" / "hook.py"
    assert "app.fleet.store" in _imports(mod, typing=False)  # imported inside after_analysis
    assert "app.pipeline" in _imports(mod) and "app.pipeline" not in _imports(mod, typing=False)  # types only


@pytest.mark.parametrize("path", sorted((REPO / "app" / "analysis").rglob("*.py")), ids=lambda p: p.name)
def test_analysis_imports_only_what_it_may(path: Path) -> None:
    project = sorted(m for m in _imports(path) if m.split(".")[0] in ("app", "sim"))
    bad = [m for m in project if not any(m == ok or m.startswith(ok + ".") for ok in ANALYSIS_MAY_IMPORT)]
    assert not bad, f"{path.relative_to(REPO)} imports {bad}; app.analysis may import only {ANALYSIS_MAY_IMPORT}"


MAX_IN_FUNCTION_IMPORTS = 18  # outside app/cli (which registers every command on each run, so imports late); the
# 18th: scipy.signal where sim/seat.py filters, a second of start-up to every bounded child otherwise


def _in_function_imports() -> list[tuple[Path, int]]:
    """(file, line) of every import inside a function of app (but app/cli) and sim, TYPE_CHECKING blocks left out."""
    found: list[tuple[Path, int]] = []
    for path in MODULES.values():
        if path.is_relative_to(REPO / "app" / "cli"):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        funcs = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]
        nodes = {id(n) for f in funcs for n in _import_nodes(f, typing=False)}
        found.extend((path, n.lineno) for n in _import_nodes(tree, typing=False) if id(n) in nodes)
    return sorted(set(found))


def test_an_import_inside_a_function_says_why() -> None:
    """A late import hides an arrow; each one left names its reason on its line or on the comment line above
    the run of imports it belongs to (an optional extra, a start-up cost, what a worker times)."""
    found = _in_function_imports()
    silent = []
    for path, line in found:
        lines = path.read_text(encoding="utf-8").splitlines()
        k = line - 1
        while k > 0 and "#" not in lines[k] and lines[k - 1].strip().startswith(("import ", "from ")):
            k -= 1  # up through the run of imports
        if "#" not in lines[k] and not lines[k - 1].strip().startswith("#"):
            silent.append(f"{path.relative_to(REPO)}:{line}")
    assert not silent, f"in-function imports without a reason: {silent}"
    assert len(found) <= MAX_IN_FUNCTION_IMPORTS, f"{len(found)} in-function imports; move new ones to the top"


# the classic file's sections (``[reducer]``, ``[halfshaft]``, ``[gaps.*]``) are a file format: sim/params.py reads
# and writes them and sim/layout.py translates them into the stage chain; every other reader of a vehicle takes the
# chain (``Vehicle.chain``) and the file's own dotted fields (``Vehicle.field_of``)
CLASSIC_FORMAT_FILES = ("sim/params.py", "sim/layout.py")
CLASSIC_SECTIONS = ("reducer", "halfshaft", "stages")


def _classic_reads(path: Path, root: Path = REPO) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.Attribute):
            continue
        base = ast.unparse(node.value)
        of_vehicle = base == "v" or base.endswith(("vehicle", "veh", "self.vehicle"))
        if node.attr in CLASSIC_SECTIONS or (node.attr == "gaps" and of_vehicle):
            out.append(f"{path.relative_to(root)}:{node.lineno}: {ast.unparse(node)}")
    return out


def test_only_the_file_format_reads_the_classic_sections() -> None:
    hits = [hit for root in ("app", "sim", "bench") for f in sorted((REPO / root).rglob("*.py"))
            if str(f.relative_to(REPO)) not in CLASSIC_FORMAT_FILES for hit in _classic_reads(f)]
    assert hits == []


def test_the_classic_read_check_sees_a_read(tmp_path: Path) -> None:
    f = tmp_path / "probe.py"
    f.write_text("def k(vehicle, counts):\n    return vehicle.halfshaft.stiffness, vehicle.gaps, vehicle.stages, "
                 "counts.gaps\n", encoding="utf-8")
    assert sorted(h.split(": ")[1] for h in _classic_reads(f, tmp_path)) == [
        "vehicle.gaps", "vehicle.halfshaft", "vehicle.stages"]
