"""`python -m lgs_jax fit` on several processes (`--coordinator`, `--num-processes`,
`--process-id`): the three options refused where incomplete or inconsistent, before any JAX
work (default set); two processes on localhost, 2 simulated CPU devices each, training one
model over the 4 devices, process 0 alone writing the run folder (slow set; the Python API's
two-process run, tests/parallel/test_gaussian_parallel_multihost.py, checks the model against
one process)."""

import json
import os
import sys

import pytest

from lgs_jax.cli.commands import main
from tests.parallel.processes import free_port, run_together
from tests.train.captures import tiny_capture

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.parametrize("extra, message", [
    (["--process-id", "1"], "--coordinator, --num-processes and --process-id: give all three"),
    (["--coordinator", "localhost:1", "--num-processes", "2", "--process-id", "2"],
     "--process-id: must be below --num-processes (2), got 2"),
    (["--coordinator", "localhost", "--num-processes", "2", "--process-id", "0"],
     "--coordinator: expected HOST:PORT, got 'localhost'"),
])
def test_fit_refuses_an_incomplete_set_of_process_options(tmp_path, capsys, extra, message):
    data = tiny_capture(tmp_path / "data")
    code = main(["fit", "--data", data, "--out", str(tmp_path / "run"), *extra])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_fit_on_two_processes_from_the_command_line(tmp_path):
    data, out, port = tiny_capture(tmp_path / "data", size=64), tmp_path / "run", free_port()
    env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu", LGS_JAX_CACHE="",
               XLA_FLAGS="--xla_force_host_platform_device_count=2")
    cmd = [sys.executable, "-m", "lgs_jax", "fit", "--data", data, "--out", str(out),
           "--steps", "3", "--backend", "reference", "--sh-degree", "0", "--eval-every", "100",
           "--coordinator", f"localhost:{port}", "--num-processes", "2"]
    outs = run_together([cmd + ["--process-id", str(i)] for i in range(2)], env, ROOT)
    results = [json.loads(o[o.index("{"):]) for o, _ in outs]
    assert [r["gaussian_devices"] for r in results] == [4, 4]
    assert results[0]["steps"] == results[1]["steps"] == 3
    assert results[0]["gaussians"] == results[1]["gaussians"]
    with open(out / "result.json") as f:
        assert json.load(f)["gaussian_devices"] == 4
    assert (out / "scene.ply").exists()
