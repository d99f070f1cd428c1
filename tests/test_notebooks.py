"""notebooks/*.ipynb run top to bottom: code cells executed in order, plots to the Agg backend,
IPython's `display` replaced by a no-op (CI has no IPython)."""

import json
import os
from pathlib import Path

import matplotlib
import pytest

ROOT = Path(__file__).resolve().parents[1]
IPYTHON_IMPORT = "from IPython.display import Image, Markdown, display"


@pytest.mark.slow  # renders the default scene at 1280x720 in five configurations
@pytest.mark.parametrize("name", ["precision.ipynb"])
def test_notebook_runs(name, monkeypatch):
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.chdir(ROOT / "notebooks")
    nb = json.loads((ROOT / "notebooks" / name).read_text())
    noop = lambda *a, **k: None
    scope = {"__name__": "__main__", "display": noop, "Image": noop, "Markdown": noop}
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            source = "".join(cell["source"]).replace(IPYTHON_IMPORT, "")
            exec(compile(source, f"{name}:{cell['id']}", "exec"), scope)
    assert os.getcwd() == str(ROOT)
    plt.close("all")
