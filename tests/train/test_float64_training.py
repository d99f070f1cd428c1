"""`FitConfig.precision = "float64"`: training whose every float is float64 (the Gaussians,
Adam's moments, the strategy's accumulators, the targets, the renders and their gradients),
checked where a float32 value would show: the gradients of two different float64 backends agree
to float64 rounding, which a float32 intermediate in either would break (the slow set), and a
command-line run keeps every float of its outputs float64. (tests/conftest.py turns
jax_enable_x64 on for the whole suite.)"""

import dataclasses
import json
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lgs_jax
from lgs_jax import cli, train
from lgs_jax.io.datasets import as_float
from lgs_jax.train import feed, state, step


@pytest.fixture(scope="module")
def skull(data_dir):
    """The skull at 1/32 size (33x22 pixels), 200 of its SfM points, 2 training and 1 held-out
    view."""
    path = os.path.join(data_dir, "skull")
    if not os.path.isdir(path):
        pytest.skip("skull not found")
    d = lgs_jax.load_dataset(path, downscale=32)
    keep = np.linspace(0, len(d.points) - 1, 200).astype(int)
    return dataclasses.replace(d, points=d.points[keep], colors=d.colors[keep],
                               train=d.train[:2], test=d.test[:1])


def _grads(skull, tmp_path, backend: str, precision: str):
    """The first step's parameter gradients on `backend` in `precision` (DefaultStrategy: the
    screen-space gradients too)."""
    config = train.FitConfig(data=skull.path, out=str(tmp_path), steps=2, precision=precision,
                             backend=backend)
    rd = feed.prepare(skull)
    setup = train.Setup.of(config, rd.scene_scale, backend)
    st = state.fresh(config, setup, rd, lambda m: None)
    cams = jax.tree.map(lambda x: x[:2], rd.train_cams)  # one size: the stack's
    targets = jnp.asarray(as_float(rd.train_images[:2])).astype(precision)
    (_, _), (grads, screen, _) = step.loss_and_grads(
        setup, st.capacity, None, st.pool, cams, targets, jnp.asarray(rd.background), 0,
        jnp.arange(2))
    return {k: np.asarray(v) for k, v in dict(grads, screen=screen).items()}


def _worst(a: dict, b: dict) -> float:
    """The largest difference of any gradient relative to the largest gradient (of any field:
    some are zero up to rounding, the quaternions' of the isotropic start, the SH bands
    masked at degree 0)."""
    return (max(float(np.max(np.abs(a[k] - b[k]))) for k in b)
            / max(float(np.max(np.abs(b[k]))) for k in b))


@pytest.mark.slow  # float64 per kernel (the default set: the float64 CLI run below)
def test_float64_gradients_agree_across_backends(skull, tmp_path):
    """tiles and pallas (two algorithms; pallas compiled on a GPU, interpreted elsewhere) in
    float64: gradients within 1e-9 of each other, every one float64. Either in float32 differs
    from them by 1e-6 of the largest and more, so the bound tells float32 arithmetic anywhere
    in either path (`reference` against `tiles` in float64: tests/backends/test_gradients.py)."""
    f64 = {b: _grads(skull, tmp_path, b, "float64") for b in ("tiles", "pallas")}
    assert all(v.dtype == np.float64 for g in f64.values() for v in g.values())
    assert _worst(f64["pallas"], f64["tiles"]) < 1e-9


def test_float64_needs_x64():
    """No silent float32: without jax_enable_x64 a `ValueError` names precision."""
    with jax.enable_x64(False), pytest.raises(ValueError, match="precision: float64 needs "
                                                                "jax_enable_x64"):
        train.Setup(precision="float64")
    with pytest.raises(ValueError, match="precision: not with gaussian_devices"):
        train.FitConfig(data="d", out="o", precision="float64", gaussian_devices=2)


def test_fit_cli_precision_float64_keeps_float64_throughout(data_dir, tmp_path):
    """`fit --precision float64` (the command line turns x64 on), a few steps with a
    refinement: every float of its checkpoint (pool, Adam state, the strategy's accumulators)
    is float64, scene.ply holds doubles, result.json says so (trained on every view: no
    evaluation's programs to compile; SH degree 0: within 4 steps the higher bands are masked
    anyway, `Recipe.sh_every`, and their evaluation costs the compiles a fifth of this test's
    CPU time; a pool of 128 slots, which the refinements never outgrow: one step compiled,
    not a second for a doubled pool, whose padding keeps each array's dtype:
    tests/train/test_strategy.py)."""
    path = os.path.join(data_dir, "lego_train")
    if not os.path.isdir(path):
        pytest.skip("lego_train not found")
    out = str(tmp_path / "run")
    assert cli.main(["fit", "--data", path, "--crop", "80", "80", "16", "16", "--init-points",
                     "50", "--steps", "4", "--out", out, "--refine-start-iter", "1",
                     "--refine-every", "2", "--precision", "float64", "--train-on-all",
                     "--sh-degree", "0", "--pool-size", "128"]) == 0
    result = json.load(open(os.path.join(out, "result.json")))
    assert result["precision"] == "float64" and result["pool_size"] == 128
    ckpt = np.load(os.path.join(out, "checkpoint.npz"))
    floats = {k: ckpt[k].dtype for k in ckpt.files if ckpt[k].dtype.kind == "f"}
    assert floats and set(floats.values()) == {np.dtype(np.float64)}, floats
    assert lgs_jax.load_ply(os.path.join(out, "scene.ply")).means.dtype == np.float64
