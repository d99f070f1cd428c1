"""Ctrl-C during `python -m lgs_jax fit` (lgs_jax.train.interrupt): the run stops at the next step
boundary, writes a checkpoint (also before its first step: `--resume` then has one), prints the
command that resumes it and exits with 130, without a traceback or an abort. (Ctrl-C between
steps, resumed to the same bits: tests/train/test_train.py.)"""

import json
import os
import shlex
import signal
import subprocess
import sys
import time

import pytest

from lgs_jax import cli, train
from lgs_jax.cli import fit as fit_cmd


def test_ctrl_c_writes_a_checkpoint_and_prints_how_to_resume(data_dir, tmp_path):
    lego = os.path.join(data_dir, "lego_train")
    if not os.path.isdir(lego):
        pytest.skip("lego_train not found")
    out = str(tmp_path / "run")
    args = ["fit", "--data", lego, "--out", out, "--steps", "50", "--crop", "80", "80", "32",
            "32", "--init-points", "100", "--backend", "reference"]
    child = subprocess.Popen([sys.executable, "-m", "lgs_jax", *args], stderr=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True,
                             env=dict(os.environ, PYTHONPATH=os.getcwd(), PYTHONUNBUFFERED="1"))
    deadline, line = time.time() + 300, ""
    while "Gaussians in a pool" not in line and time.time() < deadline:
        line = child.stdout.readline()  # the run's start is logged: its Ctrl-C handler is on
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=300)
    assert child.returncode == 130, err[-3000:]
    assert "Traceback" not in err and "terminate called" not in err, err[-3000:]
    step = json.load(open(os.path.join(out, "checkpoint.json")))["step"]
    assert f"stopped after step {step} of 50" in err, err[-2000:]
    command = err.rsplit("resumes it:\n", 1)[1].strip()
    assert command.startswith("python -m lgs_jax fit --data ") and command.endswith(
        " --resume")
    config = fit_cmd.config_of(cli.parser().parse_args(shlex.split(command)[3:]))
    assert config.resume and config.out == out
    train.check_out(config, config.data)  # the folder takes the command: it can resume
