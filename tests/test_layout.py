"""The package reads one way: each layer imports only from the layers below it.

The layers, bottom to top (docs/architecture.md draws them):

    base  <  logs  <  vehicle  <  physics  <  sim  <  learn  <  diagnose
          <  planning  <  report  <  cli

Every ``import`` counts, also those inside functions and under
``TYPE_CHECKING``: a type-only import is still a dependency of the reader.
Within a layer, modules may import each other but never in a circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "omavctl"

#: Layer of every module, by its dotted-name prefix (the longest prefix wins).
LAYERS = {
    "omavctl": 0,  # the package root: only __version__
    "omavctl.base": 0,
    "omavctl.logs": 1,
    "omavctl.vehicle": 2,
    "omavctl.rotors": 2,  # the rotor list of a vehicle file (motors:)
    "omavctl.physics": 3,
    "omavctl.sim": 4,
    "omavctl.learn": 5,
    "omavctl.diagnose": 6,
    "omavctl.planning": 7,
    "omavctl.report": 8,
    "omavctl.cli": 9,
    "omavctl.cliout": 9,
    "omavctl.guard": 9,
    "omavctl.__main__": 9,
}

MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 500


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def layer_of(module: str) -> int:
    """Layer of a dotted module name (longest matching prefix of :data:`LAYERS`)."""
    best = max((p for p in LAYERS if module == p or module.startswith(p + ".")), key=len)
    return LAYERS[best]


def _imported(module: str, node: ast.Import | ast.ImportFrom) -> list[str]:
    """omavctl modules an import statement of ``module`` loads."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.split(".")[0] == "omavctl"]
    if node.level:
        package = module.split(".")
        if MODULES[module].name != "__init__.py":
            package = package[:-1]
        package = package[: len(package) - node.level + 1]
        target = ".".join(package + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    if target.split(".")[0] != "omavctl":
        return []
    out = []
    for alias in node.names:
        sub = f"{target}.{alias.name}"
        out.append(sub if sub in MODULES else target)
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the omavctl modules it imports (anywhere in its body)."""
    graph: dict[str, set[str]] = {}
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text(), str(path))
        deps = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import | ast.ImportFrom):
                deps.update(_imported(module, node))
        deps.discard(module)
        graph[module] = deps
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_every_module_has_a_layer():
    assert "omavctl.cli" in MODULES and "omavctl.physics.effects" in MODULES
    for module in MODULES:
        layer_of(module)  # raises ValueError (max of nothing) when unmapped


def test_no_import_goes_up_a_layer():
    upward = [
        f"{m} (layer {layer_of(m)}) imports {d} (layer {layer_of(d)})"
        for m, deps in import_graph().items()
        for d in sorted(deps)
        if layer_of(d) > layer_of(m)
    ]
    assert upward == []


def test_no_import_circles():
    # the package roots re-export their modules, so a package imports its
    # children and a child importing its own package root would close a
    # circle that Python resolves only by luck of the import order
    assert _cycles(import_graph()) == []


def test_the_checks_catch_what_they_are_for():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]
    assert layer_of("omavctl.physics.effects") == 3
    assert layer_of("omavctl.cli") == 9 and layer_of("omavctl.cliout") == 9
    assert layer_of("omavctl") == 0


def _long_functions() -> list[str]:
    out = []
    for module, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                assert node.end_lineno is not None
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    out.append(f"{module}.{node.name}: {lines} lines")
    return out


@pytest.mark.parametrize("kind", ["functions", "modules"])
def test_no_long_functions_or_modules(kind):
    if kind == "functions":
        offenders = _long_functions()
    else:
        offenders = [
            f"{m}: {n} lines"
            for m, p in MODULES.items()
            if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
        ]
    assert offenders == []


def test_the_architecture_page_draws_every_layer():
    page = (PACKAGE.parent / "docs" / "architecture.md").read_text()
    packages = {m for m in MODULES if m.count(".") == 1 and MODULES[m].name == "__init__.py"}
    for package in sorted(packages):
        assert f"{package.replace('.', '/')}/" in page, f"docs/architecture.md: {package}"


def test_the_savitzky_golay_filter_sits_below_the_residual():
    """learn/signal.py reached 496 lines (session 17): the filter on arrays (the
    derivative and the kernel that holds commands alike) is its own module, which
    imports nothing of learn; the lever arm, which needs the filter but not the
    residual, reads it there; signal re-exports the same objects for its callers."""
    from omavctl.learn import savgol, signal

    def imports(module: str) -> set[str]:  # import_graph() for one module (0.7 s for all)
        tree = ast.parse(MODULES[module].read_text())
        nodes = [n for n in ast.walk(tree) if isinstance(n, ast.Import | ast.ImportFrom)]
        return {d for n in nodes for d in _imported(module, n)}

    assert not {
        d for d in imports("omavctl.learn.savgol") if layer_of(d) >= LAYERS["omavctl.learn"]
    }
    lever = imports("omavctl.learn.imu_lever")
    assert "omavctl.learn.savgol" in lever and "omavctl.learn.signal" not in lever
    for name in ("SavitzkyGolay", "usable_segments", "DEFAULT_SG_WINDOW", "DEFAULT_SG_ORDER"):
        assert getattr(signal, name) is getattr(savgol, name) and name in signal.__all__


def test_the_slowest_test_files_are_handed_out_first():
    """`make test` keeps the file order of tests/conftest.py (slowest first), which
    xdist's default reorder (most tests first) would undo; every file named exists."""
    from conftest import SLOW_FIRST

    tests = PACKAGE.parent / "tests"
    assert [name for name in SLOW_FIRST if not (tests / name).is_file()] == []
    assert len(set(SLOW_FIRST)) == len(SLOW_FIRST)
    recipe = (PACKAGE.parent / "Makefile").read_text().split("\ntest: lint\n")[1].splitlines()[0]
    assert "-n 2 --dist loadfile --no-loadscope-reorder" in recipe
