"""Several hosts (`jax.distributed.initialize`), as far as one machine allows: two processes
on the CPU, 2 simulated devices each, one mesh of 4 over both, render the sharded scene as one
device does (tests/parallel/multihost_child.py)."""

import os
import socket
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_gaussian_parallel_two_processes(tmp_path):
    path, port = tmp_path / "multihost.npz", _free_port()
    env = dict(os.environ, PYTHONPATH=ROOT)
    procs = [subprocess.Popen([sys.executable, "-m", "tests.parallel.multihost_child", str(i),
                               str(port), str(path)], env=env, cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(2)]
    try:
        outs = [p.communicate(timeout=600) for p in procs]
    finally:
        for p in procs:
            p.kill()
    for p, (_, err) in zip(procs, outs):
        assert p.returncode == 0, err[-3000:]
    res = np.load(path)
    assert bool(res["gathered"]) and not res["overflow"].any()
    for k in ("image", "alpha", "depth"):
        assert np.array_equal(res[k], res[f"one/{k}"]), k
