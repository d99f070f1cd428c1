"""Gaussian parallelism (`lgs_jax.parallel`): a scene split over 1, 2 or 4 simulated CPU devices
renders the bits of the one-device `render`, its gradients stay within the stated bound of the
one-device gradients (per Gaussian and field: the slow set), uneven shards and bands change
nothing, an exchange overflow is reported and grown out of, runs repeat their bits, and a 2 x 2
mesh (views x Gaussians) renders each view of a batch, and one camera on every row, as `render`
does.

The renders run in child processes (tests/parallel/sharded_child.py: JAX simulates 4 devices
only when told before it starts); the cases here check their results."""

import os
import subprocess
import sys

import numpy as np
import pytest

from tests import scenes

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
IMAGES = ("image", "alpha", "depth", "counts")
N = 37  # the child's scenes' Gaussians (sharded_child.N: importing it would start its JAX)
PROJECTED = ("mean2d", "conic", "depth", "opacity", "rgb")


def _run_child(tmp_path, part: str):
    """The child's results for `part` (one process per test: pytest-xdist runs tests of a module
    on several workers, which would each run a shared fixture's child again)."""
    path = tmp_path / f"{part}.npz"
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT)
    done = subprocess.run([sys.executable, "-m", "tests.parallel.sharded_child", str(path), part],
                          env=env, cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    return dict(np.load(path))


def _same_bits(res, a: str, b: str, keys=IMAGES):
    for k in keys:
        x, y = res[f"{a}/{k}"], res[f"{b}/{k}"]
        assert x.shape == y.shape and np.array_equal(x, y), f"{a}/{k} differs from {b}/{k}"


def _forward_matches(res, tag: str, name: str):
    one, sharded = f"{tag}/{name}/one/out", f"{tag}/{name}/0/out"
    _same_bits(res, one, sharded)
    assert np.array_equal(res[f"{sharded}/visible"][:N], res[f"{one}/visible"])
    assert not res[f"{tag}/{name}/0/overflow"].any()


def _within_projected_bound(res, tag: str, dtype):
    """|ĝ_sharded − ĝ_one| <= 2·γ_(K−1)·Σ_t |r_t| per Gaussian and projected field
    (lgs_jax.parallel.gaussian_parallel), r_t the Gaussian's gradient row of tile t alone."""
    _same_bits(res, f"{tag}/one/out", f"{tag}/sharded/out")  # the forward: the same bits
    u = np.finfo(dtype).eps / 2
    k = np.maximum(res[f"{tag}/tiles"] - 1, 0).astype(np.float64)
    gamma = k * u / (1 - k * u)
    for f in PROJECTED:
        one, sharded = res[f"{tag}/one/{f}"], res[f"{tag}/sharded/{f}"]
        rows = res[f"{tag}/rows/{f}"].astype(np.float64)
        # the tile rows are the whole gradient's parts: they add up to it (to rounding)
        np.testing.assert_allclose(rows.sum(0), one, rtol=0, atol=1e-5 * np.abs(one).max() + 1e-30)
        bound = 2 * gamma.reshape((-1,) + (1,) * (one.ndim - 1)) * np.abs(rows).sum(0)
        err = np.abs(sharded.astype(np.float64) - one)
        assert np.all(err <= bound), (f, float(np.max(err - bound)))


def _params_close(res, tag: str, name: str, rtol: float):
    """Gradients w.r.t. the Gaussians and the background: the projected fields' difference
    through the projection's backward, relative to each field's largest gradient."""
    for f in scenes.FIELDS + ("background",):
        one, sharded = res[f"{tag}/{name}/one/grad/{f}"], res[f"{tag}/{name}/0/grad/{f}"]
        scale = np.abs(one).max()
        assert np.abs(sharded - one).max() <= rtol * scale, (f, np.abs(sharded - one).max() / scale)


def test_gaussian_parallel_matches_one_device(tmp_path):
    res = _run_child(tmp_path, "render")
    # float64 on 4 devices: 37 Gaussians in 4 blocks of 10 (3 padding rows, not counted), one
    # band empty; the uniform scene and one crowded into the top band (band 0 receives nearly
    # every record): the forward to the bit, the gradients to the bound's rounding
    for name in ("uniform", "concentrated"):
        _forward_matches(res, "f64d4", name)
        _params_close(res, "f64d4", name, rtol=1e-12)
        a, b = f"f64d4/{name}/0", f"f64d4/{name}/1"  # run twice: the same bits
        _same_bits(res, f"{a}/out", f"{b}/out")
        _same_bits(res, f"{a}/grad", f"{b}/grad", scenes.FIELDS + ("background",))
    assert res["f64d4/concentrated/one/out/counts"].sum() == N
    sent = res["f64d4/concentrated/0/exchange_counts"]  # [source, destination]
    assert sent[:, 0].sum() > sent[:, 1:].sum() and not sent[:, 3].any()
    # 2 x 2 mesh (views x Gaussians), 2 views from an exchange capacity of 2 and 16 pairs: the
    # overflows are reported (flags, counts needed; the pairs of the records left behind
    # counted too) and grown out of at once; each view then is `render` of it alone
    calls = res["growth/calls"]  # (capacity, exchange capacity, exchange overflow, records
    # required, pair overflow, pairs required)
    assert calls.tolist() == [[16, 2, 1, 14, 1, 97], [128, 16, 0, 14, 0, 97]]
    assert res["growth/settled"].tolist() == [128, 16]
    _same_bits(res, "views/one", "views/sharded")
    assert np.array_equal(res["views/sharded/visible"][:, :N], res["views/one/visible"])
    # one camera on the 2 x 2 mesh: every row renders it (a Gaussian-parallel run's held-out
    # views), the bits of `render`
    _same_bits(res, "single/one", "single/sharded")
    assert np.array_equal(res["single/sharded/visible"][:N], res["single/one/visible"])


# CI time (a child compiling three float32 programs): the default set checks the sharded
# gradients in test_gaussian_parallel_matches_one_device (float64 on 4 devices, every field and
# the background within 1e-12 of the one-device gradients' largest, through the band
# compositing `composite_sharded` shares with `render_sharded`) and float32 training's drift
# within `sharded.drift_bound` in test_gaussian_parallel_training.py; this float32 bound per
# Gaussian and field is the slow set's, as the float64 one on 4 devices is
@pytest.mark.slow
def test_gaussian_parallel_gradients_within_the_bound(tmp_path):
    # float32 on 2 devices, from the projected Gaussians (`composite_sharded`)
    _within_projected_bound(_run_child(tmp_path, "bound"), "bound32d2", np.float32)


@pytest.mark.slow
def test_gaussian_parallel_on_one_and_four_devices(tmp_path):
    res = _run_child(tmp_path, "slow")
    _forward_matches(res, "f32d1", "uniform")  # one device: forward and backward to the bit
    _same_bits(res, "f32d1/uniform/one/grad", "f32d1/uniform/0/grad",
               scenes.FIELDS + ("background",))
    _forward_matches(res, "f32d4", "uniform")
    _params_close(res, "f32d4", "uniform", rtol=1e-4)
    _within_projected_bound(res, "bound64d4", np.float64)
    _same_bits(res, "eager/one", "eager/sharded")  # eager: buffers counted first, nothing lost
    assert res["eager/capacities"].tolist() == [128, 8]
    assert res["eager/refused"].tolist() == [8, 2]  # an overflow raises, with the count needed
