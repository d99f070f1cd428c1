"""Execute the notebooks in place, so that the committed .ipynb files show their outputs.

    pip install nbclient ipykernel     (once; not needed to run the notebooks or their CI check)
    python -m notebooks.refresh [NAME.ipynb ...]

From the repository root, on the CPU (JAX_PLATFORMS=cpu is set for the kernel: the committed
outputs are the CPU's). Each notebook runs top to bottom in a fresh Python kernel with the
repository as its working directory (`nbclient`); its outputs, and nothing else, are replaced.
Figures are PNG at `DPI` so that the files stay small. The data the notebooks read is looked up
where tests/conftest.py looks (../shared/data, or LGS_JAX_DATA).
tests/test_notebooks.py checks that the notebooks run; it does not need nbclient.
"""

from __future__ import annotations

import argparse
import os

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
NOTEBOOKS = ("precision.ipynb", "train_real_capture.ipynb")
DPI = 72
SETUP = (f"%config InlineBackend.figure_formats = ['png']\n"
         f"%config InlineBackend.rc = {{'figure.dpi': {DPI}}}")
"""Run before the first cell (not stored): small PNG figures."""


def refresh(name: str, timeout: int = 1200) -> None:
    import nbclient
    import nbformat
    from nbclient.util import run_sync

    path = os.path.join(HERE, name)
    nb = nbformat.read(path, as_version=4)
    data = os.environ.get("LGS_JAX_DATA", os.path.join(ROOT, "..", "shared", "data"))
    env = dict(os.environ, JAX_PLATFORMS="cpu", LGS_JAX_DATA=os.path.normpath(data),
               TQDM_DISABLE="1",  # a progress bar's redraws are no output to keep
               PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]))
    client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                     coalesce_streams=True,
                                     resources={"metadata": {"path": ROOT}})
    with client.setup_kernel(env=env):
        run_sync(client.kc.execute_interactive)(SETUP, store_history=False, timeout=60)
        for index, cell in enumerate(nb.cells):
            client.execute_cell(cell, index)
    nb.metadata.pop("widgets", None)
    nbformat.write(nb, path)
    size = os.path.getsize(path)
    print(f"executed {name}: {size / 1e3:.0f} kB")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m notebooks.refresh", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="*", default=list(NOTEBOOKS))
    args = ap.parse_args(argv)
    for name in args.names:
        refresh(name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
