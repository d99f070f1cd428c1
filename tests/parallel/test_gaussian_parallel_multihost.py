"""Several hosts (`jax.distributed.initialize`), as far as one machine allows: two processes
on the CPU, 2 simulated devices each, one mesh of 4 over both, render the sharded scene as one
device does (tests/parallel/multihost_child.py); read sharded and replicated arrays alike
(`parallel.to_host`) and refuse by field name what `fit` does not take across processes, a run
folder that process 0 refuses stopping both; and train one model with `fit` (Gaussian parallel
over the 4 devices), process 0 alone writing the run folder, its scene within
`sharded.drift_bound` of the same run on one process of 4 devices
(tests/parallel/multihost_fit_child.py)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from lgs_jax.io.ply import load_ply
from lgs_jax.train import sharded
from tests.parallel.processes import free_port, run_together
from tests.parallel.test_gaussian_parallel_training import beyond, ply_fields
from tests.parallel.tiny_run import RECIPE

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.slow
def test_gaussian_parallel_two_processes(tmp_path):
    path, port = tmp_path / "multihost.npz", free_port()
    env = dict(os.environ, PYTHONPATH=ROOT)
    run_together([[sys.executable, "-m", "tests.parallel.multihost_child", str(i), str(port),
                   str(path)] for i in range(2)], env, ROOT)
    res = np.load(path)
    assert bool(res["gathered"]) and not res["overflow"].any()
    for k in ("image", "alpha", "depth"):
        assert np.array_equal(res[k], res[f"one/{k}"]), k


FIT_STEPS, RESUMED = 4, 7  # the child's: refinements at steps 3 and 6
PIXELS = 32 * 64 * 3  # a training view's values (`tiny_run`)


def _children(tmp_path, part: str, timeout: float = 600) -> list[str]:
    """tests.parallel.multihost_fit_child's two processes of `part` under tmp_path; where one
    fails, the other (waiting at a collective) is killed. Returns their stderr."""
    port, env = free_port(), dict(os.environ, PYTHONPATH=ROOT)
    outs = run_together([[sys.executable, "-m", "tests.parallel.multihost_fit_child", str(i),
                          str(port), str(tmp_path), part] for i in range(2)], env, ROOT,
                        timeout)
    return [err for _, err in outs]


def test_gaussian_parallel_processes_read_and_refuse(tmp_path):
    _children(tmp_path, "seam", timeout=300)
    found = [json.load(open(tmp_path / f"seam{i}.json")) for i in range(2)]
    for i, f in enumerate(found):
        # a split array gathered, a replicated one read from this process's device
        assert f["split"] == list(range(8)) and f["total"] == 28 and f["host"] == [0, 1], f
        assert f["total_replicated"] and f["writer"] == (i == 0)
        assert f["two"].startswith("gaussian_devices: 2 processes train Gaussian parallel "
                                   "over all 4 devices; got 2"), f
        assert f["rows"].startswith("devices: not with 2 processes"), f
        assert f["watch"].startswith("watch: not with 2 processes"), f
    assert found[0]["busy"].startswith(f"out: {tmp_path / 'busy'} is not empty"), found[0]
    assert found[1]["busy"] == (f"out: process 0 refused the run folder {tmp_path / 'busy'} "
                                "(its error says why)"), found[1]
    assert not (tmp_path / "refused").exists()  # refused before any folder was made


def _rows(run) -> list[dict]:
    return [json.loads(line) for line in open(run / "metrics.jsonl")]


def _one(tmp_path, part: str) -> None:
    """tests.parallel.multihost_fit_child's one process of 4 devices, `part`."""
    env = dict(os.environ, PYTHONPATH=ROOT)
    one = subprocess.run([sys.executable, "-m", "tests.parallel.multihost_fit_child", "one",
                          "0", str(tmp_path), part], env=env, cwd=ROOT, capture_output=True,
                         text=True, timeout=600)
    assert one.returncode == 0, one.stderr[-3000:]


def _counts(rows) -> list:
    return [(r.get("step"), r.get("refine_step"), r["gaussians"]) for r in rows
            if "gaussians" in r]


def _within_drift(run, ref, steps: int, scene_scale: float) -> None:
    """run's scene.ply within `sharded.drift_bound` of ref's after `steps` steps."""
    u = np.finfo(np.float32).eps / 2
    bound = sharded.drift_bound(RECIPE, steps, scene_scale)
    got, want = ply_fields(run / "scene.ply"), ply_fields(ref / "scene.ply")
    assert all(x.shape == got[k].shape for k, x in want.items())
    assert not beyond(want, got, bound, u, steps=steps).any()


@pytest.mark.slow
def test_gaussian_parallel_fit_two_processes(tmp_path):
    _children(tmp_path, "fit")
    _one(tmp_path, "fit")
    # process 0 alone wrote a run folder; process 1 made none
    run, ref = tmp_path / "p0", tmp_path / "one"
    assert not (tmp_path / "p1").exists()
    assert sorted(os.listdir(run)) == sorted(os.listdir(ref)), os.listdir(run)
    assert {"scene.ply", "checkpoint.npz", "checkpoint.json", "metrics.jsonl", "result.json",
            "heldout_v0.png"} <= set(os.listdir(run))
    result = json.load(open(run / "result.json"))
    rows = _rows(run)
    assert load_ply(str(run / "scene.ply")).num == result["gaussians"] == rows[-2]["gaussians"]
    assert result["gaussian_devices"] == 4 and result["steps"] == FIT_STEPS
    refined = [r for r in rows if "refine_step" in r]
    assert len(refined) == 1 and sum(refined[0]["per_device"]) == refined[0]["gaussians"]
    # both processes logged the same run (the loss, the held-out scores: read alike)
    logs = [json.load(open(tmp_path / f"log{i}.json")) for i in range(2)]
    assert logs[0][:-1] == logs[1][:-1], logs  # the last line: each process's times
    # the same run on one process of 4 devices: the same counts at every step, the first
    # step's loss within the rounding of its sums, the scene within `sharded.drift_bound`
    # (measured: the same bits, every step's loss and the held-out scores too)
    ref_rows = _rows(ref)
    assert _counts(rows) == _counts(ref_rows)
    u = np.finfo(np.float32).eps / 2
    a, b = rows[0]["loss"], ref_rows[0]["loss"]
    assert abs(a - b) <= PIXELS * u / (1 - PIXELS * u) * (a + 1), (a, b)
    scale = float(logs[0][0].split("scene scale ")[1]) + 5e-4  # logged to 3 decimals
    _within_drift(run, ref, FIT_STEPS, scale)
    # resumed to RESUMED steps on both processes from process 0's checkpoint (every process
    # reads it), and the reference from its own: process 1 still writes nothing
    _children(tmp_path, "resume")
    _one(tmp_path, "resume")
    assert not (tmp_path / "p1").exists()
    resumed = [json.load(open(tmp_path / f"resumed{i}.json")) for i in range(2)]
    assert resumed[0][0] == resumed[1][0] == (f"resumed at step {FIT_STEPS} "
                                              f"({result['gaussians']} Gaussians)"), resumed
    rows, ref_rows = _rows(run), _rows(ref)
    assert [r["step"] for r in rows if "loss" in r] == list(range(1, RESUMED + 1))
    assert _counts(rows) == _counts(ref_rows)
    assert len([r for r in rows if "refine_step" in r]) == 2
    result = json.load(open(run / "result.json"))
    assert load_ply(str(run / "scene.ply")).num == result["gaussians"]
    assert result["steps"] == RESUMED
    _within_drift(run, ref, RESUMED, scale)
