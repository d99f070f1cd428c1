"""The code stays readable: no module over 500 lines, no function over 80, no import cycle
between modules (module-level imports; imports inside functions count too, since they are how
cycles used to be dodged), in the library and in the packages beside it."""

import ast
import pathlib

import pytest

PACKAGES = [pathlib.Path(__file__).parent.parent / name
            for name in ("lgs_jax", "numerics", "benchmarks")]
FILES = sorted(f for pkg in PACKAGES for f in pkg.rglob("*.py"))


def _module(path: pathlib.Path) -> str:
    root = path.parent
    while (root / "__init__.py").exists():
        root = root.parent
    return ".".join(path.relative_to(root).with_suffix("").parts).removesuffix(".__init__")


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_module_and_function_sizes(path):
    source = path.read_text()
    assert len(source.splitlines()) <= 500, f"{path}: over 500 lines"
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            lines = node.end_lineno - node.lineno + 1
            assert lines <= 80, f"{path}:{node.lineno} {node.name} has {lines} lines"


def _imports(path: pathlib.Path, module: str, known: set[str]) -> set[str]:
    """Package modules `path` imports (relative or absolute, anywhere in the file)."""
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[:len(parts) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            for alias in node.names:
                name = f"{base}.{alias.name}"
                found.add(name if name in known else base)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
    return {m for m in found if m in known and m != module}


def test_no_import_cycles():
    modules = {_module(f): f for f in FILES}
    known = set(modules)
    graph = {m: _imports(f, m, known) for m, f in modules.items()}
    # A package's __init__ importing its own submodules is how registries work: not a cycle.
    graph = {m: {d for d in deps if not d.startswith(m + ".")} for m, deps in graph.items()}
    state: dict[str, int] = {}

    def visit(m, stack):
        state[m] = 1
        for d in graph[m]:
            if state.get(d) == 1:
                cycle = stack[stack.index(d):] + [d]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if d not in state:
                visit(d, stack + [d])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
