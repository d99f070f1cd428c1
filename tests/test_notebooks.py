"""notebooks/*.ipynb: in the default set, each code cell compiles and every project name it
uses exists (`lgs_jax.x`, `train.X(field=...)`: attributes and keyword arguments of the project's
modules, read from the cells' imports), and the committed files carry their outputs
(`python -m notebooks.refresh` executes them in place) and stay small; in the slow set they run
top to bottom: code cells executed in order, plots to the Agg backend, IPython's `display`
replaced by a no-op (CI has no IPython)."""

import ast
import importlib
import inspect
import json
import os
from pathlib import Path

import matplotlib
import pytest

ROOT = Path(__file__).resolve().parents[1]
IPYTHON_IMPORT = "from IPython.display import Image, Markdown, display"


NEEDS_DATA = {"train_real_capture.ipynb": "skull"}  # folders of ../shared/data
NOTEBOOKS = ["precision.ipynb", "train_real_capture.ipynb"]
PROJECT = ("lgs_jax", "numerics")  # the packages whose names the cells are checked against


def _code_cells(name: str) -> list[tuple[str, str]]:
    """(cell id, source without the IPython import) of each code cell of notebooks/`name`."""
    nb = json.loads((ROOT / "notebooks" / name).read_text())
    return [(cell["id"], "".join(cell["source"]).replace(IPYTHON_IMPORT, ""))
            for cell in nb["cells"] if cell["cell_type"] == "code"]


def _imported(tree: ast.AST) -> dict:
    """The project's modules and names the cells import: {bound name: object}."""
    bound = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in PROJECT:
                    bound[(a.asname or a.name).split(".")[0]] = importlib.import_module(
                        a.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and node.module.split(".")[0] in PROJECT:
            module = importlib.import_module(node.module)
            for a in node.names:
                bound[a.asname or a.name] = (getattr(module, a.name) if hasattr(module, a.name)
                                             else importlib.import_module(
                                                 f"{node.module}.{a.name}"))
    return bound


def _resolved(node, bound: dict):
    """The object `node` (a name or an attribute chain on one) names, or None where it is not
    one of `bound`; AssertionError where an attribute is missing."""
    if isinstance(node, ast.Name):
        return bound.get(node.id)
    if isinstance(node, ast.Attribute):
        owner = _resolved(node.value, bound)
        if owner is None:
            return None
        assert hasattr(owner, node.attr), f"line {node.lineno}: {ast.unparse(node)} is gone"
        return getattr(owner, node.attr)
    return None


def _ours(obj) -> bool:
    """Whether `obj` is a function or class of the project (its keyword arguments checked)."""
    return callable(obj) and (getattr(obj, "__module__", None) or "").split(".")[0] in PROJECT


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_cells_compile_and_name_what_exists(name):
    """What running the notebook (slow set) would find first, without running it: every code
    cell compiles, and each project name its cells use (attribute chains on the modules and
    names they import from lgs_jax and numerics) exists, with the keyword arguments it is
    called with."""
    sources = _code_cells(name)
    for cell, source in sources:
        compile(source, f"{name}:{cell}", "exec")
    tree = ast.parse("\n".join(source for _, source in sources))
    bound = _imported(tree)
    assert bound, f"{name}: imports nothing from {PROJECT}"
    for node in ast.walk(tree):
        _resolved(node, bound)  # each attribute chain on a project name
        if not isinstance(node, ast.Call) or not _ours(called := _resolved(node.func, bound)):
            continue
        params = inspect.signature(called).parameters.values()
        if not any(p.kind == p.VAR_KEYWORD for p in params):
            for k in node.keywords:
                assert k.arg is None or k.arg in {p.name for p in params}, \
                    f"{name}: line {node.lineno}: {ast.unparse(node.func)} takes no {k.arg}="


# running them takes minutes on a CPU (precision.ipynb renders the default scene at 1280x720 in
# five configurations; train_real_capture.ipynb trains for 40 steps): slow set
@pytest.mark.slow
@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs(name, monkeypatch):
    from tests.conftest import DATA

    if name in NEEDS_DATA and not os.path.isdir(os.path.join(DATA, NEEDS_DATA[name])):
        pytest.skip(f"{NEEDS_DATA[name]} not found in {DATA}")
    monkeypatch.setenv("LGS_JAX_DATA", os.path.normpath(DATA))
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.chdir(ROOT / "notebooks")
    noop = lambda *a, **k: None
    scope = {"__name__": "__main__", "display": noop, "Image": noop, "Markdown": noop}
    for cell, source in _code_cells(name):
        exec(compile(source, f"{name}:{cell}", "exec"), scope)
    assert os.getcwd() == str(ROOT)
    plt.close("all")


MAX_BYTES = 1_000_000  # per notebook: PNG outputs at notebooks.refresh.DPI


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_is_committed_executed_and_small(name):
    """Every code cell ran, once each and in order (a cell edited or added without
    `python -m notebooks.refresh` has no execution count), and the file is under MAX_BYTES."""
    path = ROOT / "notebooks" / name
    nb = json.loads(path.read_text())
    counts = [cell.get("execution_count") for cell in nb["cells"] if cell["cell_type"] == "code"]
    assert counts == list(range(1, len(counts) + 1)), f"{name}: run python -m notebooks.refresh"
    assert path.stat().st_size < MAX_BYTES, f"{name}: {path.stat().st_size} bytes"
