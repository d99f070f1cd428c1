"""lgs_jax.train: SSIM (scikit-image's and the 3DGS loss's), the recipe's learning rates,
initialisation, the view order; `fit` on a tiny downscaled skull (the loss falls and the
Gaussian count changes, resume is bit-identical, a non-finite step is skipped and reported);
the `fit` CLI (outputs, run-directory rules, lego_train) and the progress bar."""

import csv
import dataclasses
import functools
import io
import json
import os
import signal
import subprocess
import sys
import threading
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.ndimage
from skimage.metrics import structural_similarity

import lgs_jax
from lgs_jax import cli, train
from lgs_jax.io.datasets import as_float
from lgs_jax.train import ahead, appearance, init, loop, report, state
from lgs_jax.train import feed as train_data

from tests import oracle
from tests.compare import ALPHA_CAP, F64_ATOL, STOP_INCLUSIVE

from .captures import tiny_capture


def test_ssim_equals_scikit_image():
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 1, (40, 48, 3))
    b = np.clip(a + rng.normal(0, 0.1, a.shape), 0, 1)
    want = structural_similarity(a, b, channel_axis=-1, data_range=1.0, gaussian_weights=True,
                                 sigma=1.5, use_sample_covariance=False)
    assert abs(float(train.ssim(jnp.asarray(a), jnp.asarray(b))) - want) < 1e-10
    assert abs(float(train.ssim(jnp.asarray(a), jnp.asarray(a))) - 1.0) < 1e-12


@pytest.mark.parametrize("padding", ["same", "valid"])
def test_ssim_written_out_gradient_equals_jax_gradient_of_the_reference(padding):
    """Both images' gradients: to float64 rounding in float64, and in float32 no further from
    the float64 gradient than JAX's own float32 gradient of the reference is (x 2)."""
    rng = np.random.default_rng(2)
    a = rng.uniform(0, 1, (23, 31, 3))
    b = np.clip(a + rng.normal(0, 0.15, a.shape), 0, 1)
    grad = lambda f, dt: jax.jit(jax.grad(lambda x, y: f(x, y, padding=padding), (0, 1)))(
        jnp.asarray(a, dt), jnp.asarray(b, dt))
    exact = grad(train.losses.ssim_reference, jnp.float64)
    ours = grad(train.ssim, jnp.float64)
    ours32, ref32 = grad(train.ssim, jnp.float32), grad(train.losses.ssim_reference, jnp.float32)
    for e, o, o32, r32 in zip(exact, ours, ours32, ref32):
        scale = float(jnp.max(jnp.abs(e)))
        assert float(jnp.max(jnp.abs(o - e))) < 1e-12 * scale
        assert float(jnp.max(jnp.abs(o32 - e))) <= 2 * float(jnp.max(jnp.abs(r32 - e))) + 1e-9
    with pytest.raises(ValueError, match="padding: expected 'same' or 'valid'"):
        train.ssim(jnp.asarray(a), jnp.asarray(b), padding="full")


def test_loss_ssim_is_zero_padded_over_every_pixel():
    """3DGS's SSIM: conv2d with the 11-tap Gaussian window and zero padding, mean of the map."""
    rng = np.random.default_rng(1)
    a = rng.uniform(0, 1, (20, 30, 3))
    b = np.clip(a + rng.normal(0, 0.2, a.shape), 0, 1)
    w = np.exp(-0.5 * (np.arange(-5, 6) / 1.5) ** 2)
    w2 = np.outer(w, w) / w.sum() ** 2
    blur = lambda x: np.stack([scipy.ndimage.correlate(x[..., c], w2, mode="constant")
                               for c in range(3)], -1)
    mu_a, mu_b = blur(a), blur(b)
    va, vb, cov = blur(a * a) - mu_a**2, blur(b * b) - mu_b**2, blur(a * b) - mu_a * mu_b
    c1, c2 = 0.01**2, 0.03**2
    want = np.mean((2 * mu_a * mu_b + c1) * (2 * cov + c2)
                   / ((mu_a**2 + mu_b**2 + c1) * (va + vb + c2)))
    got = train.ssim(jnp.asarray(a), jnp.asarray(b), padding="same")
    assert abs(float(got) - want) < 1e-12
    loss = train.loss_fn(jnp.asarray(a), jnp.asarray(b))
    assert abs(float(loss) - (0.8 * np.mean(np.abs(a - b)) + 0.2 * (1 - want))) < 1e-12


def test_sh_schedule_adds_one_band_every_period():
    masks = [np.asarray(train.sh_mask(step, 16, 1000)) for step in (0, 999, 1000, 2500, 9000)]
    assert [int(m.sum()) for m in masks] == [1, 1, 4, 9, 16]


def test_learning_rates_are_the_recipe():
    """Adam's first update moves each parameter by its group's rate (m̂/√v̂ = ±1); the means'
    rate at update s is 1.6e-4 · scene_scale · 0.01^(s / steps)."""
    params = {k: jnp.zeros((1, 4, 3) if k == "sh" else (1, 3)) for k in train.pool.GROUPS}
    opt = train.optimizer(train.Recipe(), 1000, 2.0)
    grads = {k: jnp.ones_like(v) for k, v in params.items()}
    updates, state = opt.update(grads, opt.init(params), params)
    want = dict(means=1.6e-4 * 2.0, quats=1e-3, log_scales=5e-3, logit_opacities=5e-2,
                sh=np.array([2.5e-3] + [2.5e-3 / 20] * 3)[None, :, None])  # band 0, the others
    for k, v in want.items():
        np.testing.assert_allclose(np.asarray(updates[k]), -v + 0 * np.asarray(params[k]),
                                   rtol=1e-6)
    sched = train.optim.means_schedule(train.Recipe(), 1000, 2.0)
    np.testing.assert_allclose(float(sched(500)), 3.2e-4 * 0.1, rtol=1e-6)
    np.testing.assert_allclose(float(sched(1000)), 3.2e-6, rtol=1e-6)


def test_initial_gaussians_follow_gsplat():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3], [10, 10, 10]], float)
    g = init.initial_gaussians(pts, np.full((5, 3), 0.75), 0.1, 1.0, seed=0)
    d0 = np.sqrt(np.mean([1, 4, 9]))  # point 0: neighbours at 1, 2, 3
    np.testing.assert_allclose(np.exp(np.asarray(g.log_scales)[0]), d0, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(g.sh)[:, 0], 0.25 / 0.28209479177387814, rtol=1e-6)
    assert not np.asarray(g.sh)[:, 1:].any() and g.sh.shape == (5, 16, 3)
    np.testing.assert_allclose(1 / (1 + np.exp(-np.asarray(g.logit_opacities))), 0.1, rtol=1e-6)
    q = np.asarray(g.quats)
    assert q.min() >= 0 and q.max() < 1


@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
def test_streamed_views_are_the_steps_views_two_batches_at_most(dtype):
    images = np.random.default_rng(0).uniform(0, 255, size=(5, 4, 6, 3)).astype(dtype)
    expected = as_float(images)
    whole, streamed = (train_data.TrainViews(images, 2, 3, stream) for stream in (False, True))
    for step in range(4):
        views = train_data.views_for_step(step, 2, 5, 3)
        for source in (whole, streamed):
            targets, idx = source.args(step)
            source.prefetch(step + 1)
            np.testing.assert_array_equal(np.asarray(idx), views)
            assert targets.dtype == dtype  # as stored; the step converts them
            np.testing.assert_array_equal(np.asarray(train_data.to_float(targets)),
                                          expected[views])
            assert source.held == [step, step + 1]
    streamed.close()
    assert streamed.closed
    kept = streamed.args(3)[0]
    np.testing.assert_array_equal(np.asarray(train_data.to_float(kept)), expected[views])


class _Device:
    def __init__(self, limit):
        self.limit = limit

    def memory_stats(self):
        return None if self.limit is None else {"bytes_limit": self.limit}


@pytest.mark.parametrize("nbytes,setting,limit,want", [
    (100, True, None, True), (10**12, False, 8 * 10**9, False),
    (100, None, 8 * 10**9, True), (10**12, None, 8 * 10**9, True),
    (2 << 30, None, None, False), ((2 << 30) + 1, None, None, True)])
def test_images_stream_on_a_gpu_and_where_they_are_large_on_a_host(nbytes, setting, limit,
                                                                   want):
    assert train_data.streams(nbytes, setting, _Device(limit)) == want


def test_views_follow_one_shuffle_per_epoch():
    order = [int(train_data.views_for_step(s, 1, 5, seed=3)[0]) for s in range(10)]
    assert sorted(order[:5]) == list(range(5)) and sorted(order[5:]) == list(range(5))
    assert order[:5] != order[5:]
    batches = [train_data.views_for_step(s, 2, 5, seed=3).tolist() for s in range(5)]
    assert sum(batches, []) == order  # batches read the same stream


@pytest.fixture(scope="module")
def skull(data_dir):
    """The skull at 1/32 size (33x22 pixels), 300 of its SfM points, 2 training and 2 held-out
    views (any 4 consecutive steps then see each training view twice); the first training
    view's photo darkened (x0.6), so that its colour correction darkens against the other's."""
    path = os.path.join(data_dir, "skull")
    if not os.path.isdir(path):
        pytest.skip("skull not found")
    d = lgs_jax.load_dataset(path, downscale=32)
    keep = np.linspace(0, len(d.points) - 1, 300).astype(int)
    images = d.images.copy()
    images[d.train[0]] *= 0.6
    return dataclasses.replace(d, images=images, points=d.points[keep], colors=d.colors[keep],
                               train=d.train[:2], test=d.test[:2])


STEPS = 16
STRATEGY = train.DefaultStrategy(refine_start_iter=3, refine_every=4, grow_grad2d=1e-4,
                                 prune_opa=0.02)


def _config(data, out, **kwargs) -> train.FitConfig:
    """One configuration for every fit below, so they share one compiled step: the views' own
    parameters optimized too (pose deltas, colour corrections, appearance embeddings); SH
    degree 0 (within `STEPS` the higher bands are masked anyway, `Recipe.sh_every`, and their
    evaluation costs each compile a third more); headroom 1.5 (not the default 3), so that the
    pairs outgrow the first capacity (at step 10)."""
    recipe = train.Recipe(sh_degree=0, pose_opt=True, color_opt=True, app_opt=True)
    return train.FitConfig(data=data.path, out=str(out), steps=STEPS, recipe=recipe,
                           strategy=STRATEGY, max_gaussians=1024, pool_size=1024,
                           backend="reference", eval_every=kwargs.pop("eval_every", 100),
                           checkpoint_every=kwargs.pop("checkpoint_every", 3), pair_headroom=1.5,
                           stream_images=kwargs.pop("stream", None), **kwargs)


def _fit(data, out, **kwargs):
    hooks = {k: kwargs.pop(k) for k in ("watch", "watch_every", "log") if k in kwargs}
    hooks.setdefault("log", lambda m: None)
    return train.fit(_config(data, out, **kwargs), data, **hooks)


@pytest.fixture(scope="module")
def uninterrupted(skull, tmp_path_factory):
    """A run of `STEPS` steps, evaluated every 2 steps and watched (`fit`'s `watch`) at its
    start and after every step: (its folder, its result, the watch's calls). What
    test_fit_densifies_and_the_loss_falls reads, and the run that
    test_resume_is_bit_identical's interrupted runs end as."""
    out = tmp_path_factory.mktemp("uninterrupted")
    train.train_step.clear_cache()  # another test of this process may have compiled it
    seen = []
    result = _fit(skull, out, eval_every=2, watch=lambda *a: seen.append(a), watch_every=0)
    return out, result, seen


def test_fit_densifies_and_the_loss_falls(skull, uninterrupted, tmp_path):
    run, result, seen = uninterrupted
    rows = report.read_metrics(str(run / "metrics.jsonl"))
    steps = [r for r in rows if "loss" in r]
    assert [r["step"] for r in steps] == list(range(1, STEPS + 1))
    # watched at the start and after every step: the Gaussians as rendered, the step's metrics
    assert [step for step, _, _ in seen] == list(range(STEPS + 1))
    assert seen[0][2] == dict(gaussians=300)
    assert [(m["gaussians"], m["loss"]) for _, _, m in seen[1:]] == [
        (r["gaussians"], r["loss"]) for r in steps]
    last = seen[-1][1]
    shown = np.isfinite(np.asarray(last.logit_opacities))
    assert last.num == 1024 and shown.sum() == result["gaussians"]
    ply = lgs_jax.load_ply(str(run / "scene.ply"))
    for name in ("means", "quats", "log_scales", "logit_opacities", "sh"):
        np.testing.assert_array_equal(np.asarray(getattr(last, name))[shown],
                                      getattr(ply, name), err_msg=name)
    # training (at their optimized poses: test_resume_is_bit_identical), then held-out
    assert [c["img_name"] for c in json.load(open(run / "cameras.json"))] == [
        "02", "03", "01", "09"]
    # the saved scene scores what fit's last evaluation scored, view by view
    scores = train.evaluate(ply, skull, backend="reference", out=str(tmp_path / "eval"))
    assert scores["psnr"] == pytest.approx(result["heldout_psnr"], abs=1e-4)
    assert scores["ssim"] == pytest.approx(result["heldout_ssim"], abs=1e-5)
    assert [v["name"] for v in scores["views"]] == ["01", "09"] and scores["split"] == "test"
    assert json.load(open(tmp_path / "eval" / "metrics.json")) == scores
    assert (tmp_path / "eval" / "eval_09.png").exists()
    refines = [r for r in rows if "refine_step" in r]
    assert [r["refine_step"] for r in refines] == [4, 8, 12]
    assert sum(r["cloned"] + r["split"] + r["pruned"] for r in refines) > 0
    counts = {r["gaussians"] for r in steps}
    assert len(counts) > 1 and result["gaussians"] != 300, counts
    held = [r["heldout_psnr"] for r in rows if "heldout_psnr" in r]
    assert held[-1] > held[0] + 0.3, held  # from step 2 to the end
    first, last = (np.mean([r["loss"] for r in part]) for part in (steps[:4], steps[-4:]))
    assert last < 0.95 * first, (first, last)
    assert lgs_jax.load_ply(str(run / "scene.ply")).num == result["gaussians"]
    import matplotlib.image
    side = matplotlib.image.imread(str(run / f"heldout_{skull.names[0][:-4]}.png"))
    assert side.shape[:2] == (22, 66)  # render beside ground truth
    assert os.path.getsize(run / "curves.png") > 0 and result["skipped_steps"] == 0
    busy = 1e-3 * result["ms_per_step"] * STEPS  # steps and refinements, compiling included
    assert 0 < result["compile_seconds"] < busy <= result["seconds"]
    # the step's first trace, lowering and compile (or load) are the loop thread's
    parts = result["compile_parts"]
    assert list(parts) == ["trace", "lower", "backend", "waited"] and min(parts.values()) >= 0
    assert parts["trace"] > 0 and parts["lower"] > 0 and parts["backend"] > 0
    assert sum(parts.values()) == pytest.approx(result["compile_seconds"])
    assert result["programs_compiled"] + result["programs_loaded"] >= 2  # step, refinement
    assert result["ahead_compile_seconds"] >= 0
    parts = [result[k] for k in ("load_seconds", "step_seconds", "eval_seconds",
                                 "checkpoint_seconds", "finish_seconds")]
    assert min(parts) >= 0 and result["eval_seconds"] > 0 and result["checkpoint_seconds"] > 0
    assert abs(result["step_seconds"] - busy) < 1e-6 * busy
    assert 0 < result["device_wait_seconds"] < result["step_seconds"]
    assert sum(parts) <= result["seconds"]  # the rest: the watch, the bar, the metrics file
    # device memory by part: the first step's row (with its program's temporaries) and the
    # result; no peak on the CPU (no allocator statistics)
    first = steps[0]["memory"]
    assert all("memory" not in r for r in steps[1:]) and "peak_mib" not in steps[0]
    assert first["step_temporaries_mib"] > 0 and "mib_in_use" not in first
    mem = result["memory"]
    assert [k for k in mem if k.endswith("_mib")] == [
        "pool_mib", "optimizer_mib", "strategy_mib", "views_mib", "other_arrays_mib"]
    floats = 3 + 4 + 3 + 1 + 3 + appearance.FEATURES  # a slot's parameters (SH degree 0)
    slots = result["pool_size"]
    assert mem["pool_mib"] == pytest.approx(slots * (4 * floats + 1) / 2**20, abs=1e-3)
    assert mem["optimizer_mib"] == pytest.approx(slots * 8 * floats / 2**20, abs=2e-3)


class _Stop(Exception):
    pass


def test_resume_is_bit_identical(skull, uninterrupted, tmp_path):
    """A run that dies after step 7 (its last checkpoint: step 6) and is resumed ends with the
    same bits as the uninterrupted run (`uninterrupted`): pool, active mask, Adam state,
    strategy state, and the views' own parameters (pose deltas, colour corrections and
    appearance embeddings with their head, `view_params`) and their Adam states. The
    uninterrupted run is evaluated and watched after every step (`fit`'s `watch`), the resumed
    one streams its training images (`FitConfig.stream_images`) and is watched at its start and
    end only (`watch_every`), which change nothing; a third is stopped by Ctrl-C and resumed.
    The first training view's photo is darkened (`skull`), so that its colour correction
    darkens against the other's."""
    a_run = uninterrupted[0]

    def die(message):
        if message.startswith("step 7:"):
            raise _Stop

    lines = []
    with pytest.raises(_Stop):
        _fit(skull, tmp_path / "b", eval_every=7, log=lambda m: lines.append(m) or die(m),
             stream=True)
    assert any(m.startswith("training images streamed") for m in lines), lines
    assert json.load(open(tmp_path / "b" / "checkpoint.json"))["step"] == 6
    seen = []
    _fit(skull, tmp_path / "b", resume=True, stream=True,
         watch=lambda step, *_: seen.append(step), watch_every=1e9)
    assert seen == [6, STEPS]
    # Ctrl-C (SIGINT, here during the watch after step 4): the run stops at that step's
    # boundary, writes its checkpoint (step 4, between the periodic ones at 3 and 6) and raises
    # `Interrupted`; resumed, it ends with the same bits
    interrupt = lambda step, *_: step == 4 and os.kill(os.getpid(), signal.SIGINT)
    handler = signal.getsignal(signal.SIGINT)  # SIG_IGN where pytest was started in the background
    with pytest.raises(train.Interrupted) as stopped:
        _fit(skull, tmp_path / "c", watch=interrupt, watch_every=0)
    assert (stopped.value.step, stopped.value.steps) == (4, STEPS)
    assert json.load(open(tmp_path / "c" / "checkpoint.json"))["step"] == 4
    assert not (tmp_path / "c" / "result.json").exists()
    assert signal.getsignal(signal.SIGINT) is handler  # restored
    _fit(skull, tmp_path / "c", resume=True)
    a, b, c = (np.load(run / "checkpoint.npz") for run in (a_run, tmp_path / "b", tmp_path / "c"))
    for name in a.files:
        np.testing.assert_array_equal(a[name], c[name], err_msg=name)
    assert sorted(a.files) == sorted(b.files) and len(a.files) > 15
    # views' leaves: colour (corrections, Adam count, mu, nu), embed (the same), head (its
    # six weights, Adam count, mu, nu), then pose (deltas, ...)
    corrections, embeddings, deltas = a["views_0"], a["views_4"], a["views_27"]
    assert (corrections.shape, embeddings.shape, deltas.shape) == ((2, 12), (2, 16), (2, 9))
    for moved in (corrections, embeddings, deltas):  # two training views, moved from zero
        assert np.all(np.abs(moved).max(1) > 0)
    for centred in (corrections, embeddings):
        np.testing.assert_allclose(centred.sum(0), 0, atol=1e-7)
    saved = np.load(a_run / "appearance.npz")
    np.testing.assert_array_equal(saved["embeddings"], embeddings)
    assert list(saved["names"]) == ["02", "03"] and np.abs(saved["w3"]).max() > 0
    assert saved["features"].shape == (lgs_jax.load_ply(str(a_run / "scene.ply")).num, 32)
    colors = json.load(open(a_run / "colors.json"))
    assert [c["img_name"] for c in colors] == ["02", "03"]
    grey = [np.mean(np.asarray(c["matrix"]) @ np.full(3, 0.5) + c["offset"]) for c in colors]
    assert grey[0] < 0.5 < grey[1], grey  # the darkened photo's view renders darker
    cams = lgs_jax.load_cameras(str(a_run / "cameras.json"))  # at the moved poses
    moved = [np.abs(np.asarray(c.viewmat) - np.asarray(skull.cameras[i].viewmat)).max()
             for c, i in zip(cams, list(skull.train) + list(skull.test))]
    assert all(0 < m < 1e-2 for m in moved[:2]) and max(moved[2:]) < 1e-6, moved
    for name in a.files:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    ply = [(run / "scene.ply").read_bytes() for run in (a_run, tmp_path / "b")]
    assert ply[0] == ply[1]
    for run in "bc":
        rows = report.read_metrics(str(tmp_path / run / "metrics.jsonl"))
        assert [r["step"] for r in rows if "loss" in r] == list(range(1, STEPS + 1))


@pytest.mark.slow  # the default set: test_steps_dispatched_ahead_change_no_bit's thread run
@pytest.mark.parametrize("mode", ["thread", "process"])
def test_compiling_ahead_changes_no_bit(skull, tmp_path, mode):
    """`fit` compiles the step for the next pair capacity in a background thread (the default
    on GPUs) or a child process (through the suite's persistent cache) and takes it when the
    pairs grow past the capacity (at step 10 here); without it the step is compiled there. Same
    bits at the end, though the capacities may differ (`ahead.Stepper` takes the smallest one
    that holds the pairs): nothing depends on the capacity but drops."""
    logs = {mode: [], "off": []}
    for on, log in logs.items():
        _fit(skull, tmp_path / on, log=log.append, compile_ahead=on)
    assert any("grown" in m and "(compiled ahead;" in m for m in logs[mode]), logs[mode]
    assert any("grown" in m and "(one recompile)" in m for m in logs["off"]), logs["off"]
    a, c = (np.load(tmp_path / r / "checkpoint.npz") for r in (mode, "off"))
    for name in a.files:
        np.testing.assert_array_equal(a[name], c[name], err_msg=name)


def test_steps_dispatched_ahead_change_no_bit(skull, tmp_path, monkeypatch):
    """`fit` dispatches a step before reading the previous one's metrics where nothing between
    them reads the state (`loop._ahead`), passing it the previous one's fits as its go; where
    the previous one overflowed (0-based step 9 here: the pairs outgrow the capacity), the one
    dispatched ahead is told not to apply (`train_step`'s go: test_sizes) and both run again.
    A checkpoint after every step leaves no step to dispatch ahead, not even after a growth
    taken from the step compiled ahead (compile_ahead="thread"): the same bits."""
    order, dispatch = {}, loop._dispatch

    def tracked(run, feed, steps, step, size, go, seen):
        seen.append((step, bool(go)))
        ahead.append(step - run.st.step)  # 1: dispatched before step `step - 1` was read
        return dispatch(run, feed, steps, step, size, go)

    aheads, logs = {}, []
    for every in (3, 1):
        ahead = aheads[every] = []
        monkeypatch.setattr(loop, "_dispatch", functools.partial(tracked, seen=[]))
        order[every] = loop._dispatch.keywords["seen"]
        if every == 1:
            # the step compiled ahead at the size the first run grew to (its checkpoint's
            # capacity and rows), not at `Sizes.following`'s: that run's program (the
            # persistent cache's), not another compile. The run's sizes are `state.sizes`'
            # (`loop.Sizes` sizes Gaussian-parallel runs only).
            ckpt = json.load(open(tmp_path / "3" / "checkpoint.json"))
            grown = ckpt["capacity"], ckpt["rows"]

            class Sizes(state.Sizes):
                def following(self, size):
                    return grown

            sizes = state.sizes
            monkeypatch.setattr(state, "sizes", lambda config: Sizes(
                *dataclasses.astuple(sizes(config))))
        _fit(skull, tmp_path / str(every), checkpoint_every=every,  # growth taken from ahead:
             compile_ahead="thread" if every == 1 else None, log=logs.append)
    assert any("grown" in m and "(compiled ahead;" in m for m in logs), logs
    redo = [(9, True), (10, False), (9, True), (10, True), (11, True)]
    assert [s for s in order[3] if not s[1]] == [(10, False)], order[3]
    i = order[3].index((10, False))
    assert order[3][i - 1:i + 4] == redo and len(order[3]) == STEPS + 2, order[3]
    assert order[1] == [(s, True) for s in sorted(list(range(STEPS)) + [9])], order[1]
    assert set(aheads[3]) == {0, 1} and not any(aheads[1]), aheads
    a, b = (np.load(tmp_path / r / "checkpoint.npz") for r in "31")
    assert sorted(a.files) == sorted(b.files)
    for name in a.files:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


class _Lowered:
    def __init__(self, capacity, fail=False):
        self.capacity, self.fail = capacity, fail

    def compile(self):
        if self.fail:
            raise RuntimeError("no")
        return lambda *args: ("executable", self.capacity)


class _Jitted:
    """A stand-in for a jitted function of static `size`: called, ("jit", size); lowered, a
    `_Lowered` (failing to compile with `fail`)."""

    def __init__(self, fail=False):
        self.fail = fail

    def __call__(self, *args, size):
        return ("jit", size)

    def lower(self, *args, size):
        return _Lowered(size, self.fail)


@pytest.mark.parametrize("need,same_shapes,fail,want", [
    # the prepared size (pairs grown, their rows with them) holds the pairs and walked pairs
    ((1100, 600), True, False, ("executable", (4096, 2048))),
    ((1000, 900), True, False, None),  # a growth of the rows alone: the pairs stay
    ((4100, 600), True, False, None),  # not the pairs: the jitted step at pair_capacity(4100)
    ((1100, 2100), True, False, None),  # not the walked pairs: the step with grown rows
    ((1100, 600), False, False, None),  # the pool grew since: the jitted step
    ((1100, 600), True, True, None),  # its compile failed: the jitted step
])
def test_stepper_takes_the_step_compiled_ahead_only_where_it_fits(need, same_shapes, fail,
                                                                  want):
    sizes = ahead.Sizes(2.0, row_headroom=1.0)
    stepper = ahead.Stepper(_Jitted(fail), lambda size: dict(size=size), sizes)
    args = (jnp.zeros(3), 7)
    sig = ahead.signature(args)
    assert stepper.run(args, (1024, 800), sig) == ("jit", (1024, 800))
    stepper.prepare(args, (1024, 800), sig)  # (pair_capacity(1025, 2), its rows: 2048)
    other = sig if same_shapes else ahead.signature((jnp.zeros(4), 7))
    size, waited, taken = stepper.grow((1024, 800), need, other)
    assert taken == (want is not None) and waited >= 0
    if not taken:
        assert size == sizes.grown((1024, 800), need)
    assert stepper.run(args, size, other) == (want or ("jit", size))
    stepper.close()


@pytest.mark.parametrize("fail", [False, True])
def test_stepper_takes_a_later_steps_compile_at_its_shapes_and_size(fail):
    """`Stepper.ahead` (the next image level's step): compiled for shapes given as
    ShapeDtypeStructs; the first run of those shapes at that size takes it, another size or
    shape compiles its own; a failed compile is said and leaves the jitted step."""
    stepper = ahead.Stepper(_Jitted(fail), lambda size: dict(size=size), ahead.Sizes(1.5))
    now, later = (jnp.zeros(3, jnp.float32), 7), (jnp.zeros(5, jnp.float32), 7)
    stepper.run(now, (1024, None), ahead.signature(now))
    stepper.ahead((jax.ShapeDtypeStruct((5,), jnp.float32), 7), (2048, None))
    sig = ahead.signature(later)
    assert stepper.run(later, (4096, None), sig) == ("jit", (4096, None))  # another size
    want = ("jit", (2048, None)) if fail else ("executable", (2048, None))
    assert stepper.run(later, (2048, None), sig) == want
    assert (stepper.failure is not None) == fail and stepper.take_waited() >= 0
    assert stepper.take_waited() == 0
    stepper.close()


def test_sizes_grow_what_overflowed():
    """`ahead.Sizes`: the pairs, where they overflowed, to `pair_capacity(pairs,
    pair_headroom)` with their rows (`rows_for`: row_headroom times the pairs the capacity is
    sized for, at most a row per slot); the rows, where the walked pairs overflowed them, to
    `pair_capacity(walked, row_headroom)`, at most a row per slot; never smaller; rows of None
    (a row per pair slot) never grow."""
    sizes = ahead.Sizes(3.0, row_headroom=1.5)
    cap = lgs_jax.pair_capacity
    assert sizes.rows_for(3 * 2**20) == 3 * 2**19 and sizes.rows_for(4) == 2
    assert ahead.Sizes(1.5, 2.0).rows_for(2**20) == 2**20 and sizes.rows_for(1) == 1
    assert sizes.following((2**20, 300)) == (cap(2**20 + 1, 3.0), cap((2**20 + 1) * 1.5))
    assert sizes.following((2**20, 2**21)) == (cap(2**20 + 1, 3.0), 2**21)  # never smaller
    assert sizes.following((1024, None)) == (cap(1025, 3.0), None)
    assert sizes.grown((2**20, 300), (2**21, 100)) == (cap(2**21, 3.0), cap(2**21 * 1.5))
    assert sizes.grown((2**20, 300), (1000, 301)) == (2**20, cap(301, 1.5))
    assert sizes.grown((2**20, 300), (2**21, 2**21)) == (cap(2**21, 3.0), cap(2**21, 1.5))
    assert sizes.grown((4096, 300), (1000, 4000)) == (4096, 4096)  # at most a row per slot
    assert sizes.grown((1024, None), (1000, 5000)) == (1024, None)
    assert sizes.holds((1024, None), (1024, 10**9)) and not sizes.holds((1024, 8), (1, 9))


def test_a_non_finite_step_is_skipped_and_reported(skull, tmp_path):
    """A NaN in one training image: every step on that view changes nothing and is reported;
    the others train, and the parameters written stay finite."""
    views = [int(train_data.views_for_step(s, 1, 2, seed=0)[0]) for s in range(STEPS)]
    images = skull.images.copy()
    images[skull.train[views[4]], 3, 4, 1] = np.nan
    bad = [s + 1 for s in range(STEPS) if views[s] == views[4]]
    lines = []
    result = _fit(dataclasses.replace(skull, images=images), tmp_path, log=lines.append)
    rows = [r for r in report.read_metrics(str(tmp_path / "metrics.jsonl")) if "loss" in r]
    assert [r["step"] for r in rows if r.get("skipped")] == bad and 0 < len(bad) < STEPS
    assert result["skipped_steps"] == len(bad)
    assert [m for m in lines if "skipped" in m] == [
        f"step {s}: skipped (loss or gradients not finite)" for s in bad]
    g = lgs_jax.load_ply(str(tmp_path / "scene.ply"))
    assert g.num > 300  # the other view's steps densified
    assert all(np.isfinite(np.asarray(getattr(g, f))).all()
               for f in ("means", "quats", "log_scales", "logit_opacities", "sh"))


def _lego(data_dir):
    path = os.path.join(data_dir, "lego_train")
    if not os.path.isdir(path):
        pytest.skip("lego_train not found")
    return path


def test_lego_train_is_prepared_as_nerf_synthetic(data_dir):
    rd = train_data.prepare(_lego(data_dir), crop=(80, 80, 32, 32))
    assert rd.nerf_synthetic and rd.test_names == [f"r_{i}" for i in range(0, 100, 10)]
    assert rd.train_images.shape == (90, 32, 32, 3) and len(rd.points) == 0
    assert abs(rd.scene_scale - 1.1 * 4.7292) < 1e-3


def test_fit_cli_writes_outputs_and_refuses_mixing(data_dir, tmp_path, capsys):
    """--steps 0 (no training step: quick): outputs, then the run-directory rules. SH degree 0
    (as in the viewer's test below, which then reuses this test's compiled evaluations): the
    higher bands' evaluation adds to every render's compile, and nothing here is about them."""
    out = str(tmp_path / "run")
    args = ["fit", "--data", _lego(data_dir), "--steps", "0", "--out", out, "--init-points",
            "200", "--crop", "80", "80", "32", "32", "--backend", "reference", "--sh-degree", "0"]
    assert cli.main(args) == 0
    result = json.load(open(os.path.join(out, "result.json")))
    assert '"heldout_psnr"' in capsys.readouterr().out
    assert result["steps"] == 0 and result["ms_per_step"] is None and result["gaussians"] == 200
    for name in ("scene.ply", "metrics.jsonl", "result.json", "curves.png", "heldout_r_0.png"):
        assert os.path.getsize(os.path.join(out, name)) > 0, name
    assert cli.main(args) == 2  # an existing run is never silently mixed with a new one
    assert "--resume" in capsys.readouterr().err
    assert cli.main(args + ["--resume"]) == 2  # no checkpoint to resume from
    assert cli.main(args + ["--overwrite"]) == 0
    rows = report.read_metrics(os.path.join(out, "metrics.jsonl"))
    assert [r["step"] for r in rows] == [0] and "heldout_psnr" in rows[0]
    capsys.readouterr()
    scene = os.path.join(out, "scene.ply")
    assert cli.main(["eval", scene, "--data", _lego(data_dir), "--downscale", "25",
                     "--backend", "reference", "--split", "all", "--out", out + "/e"]) == 0
    printed = capsys.readouterr().out
    assert "all views: 100; mean PSNR" in printed and "r_99  PSNR" in printed
    assert len(json.load(open(os.path.join(out, "e", "metrics.json")))["views"]) == 100
    assert cli.main(["eval", scene + "x", "--data", _lego(data_dir)]) == 2
    assert cli.main(["eval", scene, "--data", scene]) == 2
    assert "--data" in capsys.readouterr().err


def test_fit_cli_shows_the_training_in_a_viewer(data_dir, tmp_path, monkeypatch, capsys):
    """--viewer-port: the dataset is loaded once, a viewer serves it while `fit` watches,
    the page answers, and after the run the viewer keeps serving (`viewer.wait`, stubbed)."""
    pytest.importorskip("viser")
    import socket
    import urllib.request

    from lgs_jax import viewer

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    served = []

    def wait(s):
        page = urllib.request.urlopen(f"http://127.0.0.1:{s.port}/", timeout=30).read()
        drawn = [s.server.scene.get_handle_by_name(f"/cameras/{i}") for i in (89, 90)]
        served.append((b"<html" in page, s.status, s.scene.num,
                       [d is not None for d in drawn]))  # the 90 training cameras
        s.stop()

    monkeypatch.setattr(viewer, "wait", wait)
    args = ["fit", "--data", _lego(data_dir), "--steps", "0", "--out", str(tmp_path / "run"),
            "--init-points", "200", "--crop", "80", "80", "32", "32", "--backend",
            "reference", "--sh-degree", "0", "--viewer-port", str(port), "--viewer-host",
            "127.0.0.1"]
    assert cli.main(args) == 0
    assert served == [(True, "step 0 of 0, 200 Gaussians", 256, [True, False])]
    assert "the viewer shows the trained scene" in capsys.readouterr().out


def test_fit_cli_passes_the_strategy_and_cap(tmp_path, monkeypatch):
    seen = {}
    monkeypatch.setattr(train, "fit", lambda config, *a, **k: seen.update(config=config) or {})
    base = ["fit", "--data", str(tmp_path), "--out", str(tmp_path / "o")]
    assert cli.main(base + ["--strategy", "mcmc", "--max-gaussians", "5000"]) == 0
    c = seen["config"]
    assert c.strategy == train.MCMCStrategy(cap_max=5000)
    assert c.max_gaussians == 5000 and c.downscale == 1
    assert cli.main(base + ["--downscale", "4", "--opacity-reset", "--steps", "7"]) == 0
    c = seen["config"]
    assert c.strategy == train.DefaultStrategy(opacity_reset=True)
    assert c.downscale == 4 and c.recipe.convention == "3dgs" and c.recipe.sh_degree == 3
    assert c.compile_ahead is None  # fit's default: on a GPU
    assert not c.recipe.antialiased and c.stream_images is None
    assert not (c.train_on_all or c.recipe.color_opt or c.recipe.bilateral_grid
                or c.recipe.app_opt or c.uint8_images)
    assert cli.main(base + ["--no-stream-images", "--pose-opt", "--train-on-all",
                            "--color-opt", "--bilateral-grid", "--app-opt", "--uint8-images",
                            "--sh-degree", "1", "--checkpoint-every", "20"]) == 0
    c = seen["config"]
    assert c.recipe.sh_degree == 1 and c.stream_images is False and c.recipe.pose_opt
    assert c.train_on_all and c.recipe.color_opt and c.recipe.bilateral_grid
    assert c.recipe.app_opt and c.uint8_images and c.checkpoint_every == 20
    assert cli.main(base + ["--convention", "gsplat", "--no-compile-ahead", "--antialiased"]) == 0
    c = seen["config"]
    assert c.recipe.convention == "gsplat" and c.compile_ahead == "off"
    assert c.recipe.raster == lgs_jax.RasterConfig("gsplat", antialiased=True)
    assert cli.main(base + ["--compile-ahead-process"]) == 0
    assert seen["config"].compile_ahead == "process"


def test_run_dir_rules(tmp_path):
    assert train.run_dir_problem(str(tmp_path / "new")) is None
    assert train.run_dir_problem(str(tmp_path)) is None  # empty
    (tmp_path / "metrics.jsonl").write_text("{}\n")
    assert "--resume" in train.run_dir_problem(str(tmp_path))
    assert "no checkpoint.json" in train.run_dir_problem(str(tmp_path), resume=True)
    assert train.run_dir_problem(str(tmp_path), overwrite=True) is None
    assert "exclude" in train.run_dir_problem(str(tmp_path), resume=True, overwrite=True)
    assert "not a directory" in train.run_dir_problem(str(tmp_path / "metrics.jsonl"))
    with pytest.raises(ValueError, match="out: .* is not empty"):
        train.fit(train.FitConfig(data="unused", out=str(tmp_path), steps=1))


def test_training_renders_follow_the_settings():
    """Recipe.convention and .antialiased reach the renders: an opaque Gaussian over a white
    background leaves 1 − 0.99 of it under "3dgs" and 1 − 0.999 under "gsplat"; a Gaussian
    smaller than a pixel in front of it is fainter antialiased. Each image is the float64
    oracle's of its settings, clipped; the default settings' is `render`'s, clipped, to the bit
    (one `render` compile: the others' programs differ in constants only)."""
    from lgs_jax.train import pool as P, step as S

    g = lgs_jax.Gaussians(means=jnp.array([[0.0, 0.0, 4.0], [-0.825, -0.825, 3.0]]),
                          quats=jnp.array([[1.0, 0, 0, 0]] * 2),
                          log_scales=jnp.array([[2.0] * 3, [-3.0] * 3]),
                          logit_opacities=jnp.array([30.0, 0.0]),
                          sh=jnp.array([[[0.0] * 3], [[1.0] * 3]]))
    cam = lgs_jax.Camera(viewmat=np.eye(4, dtype=np.float32), fx=20.0, fy=20.0, cx=8.0, cy=8.0,
                         width=16, height=16)
    pool = P.from_gaussians(g)
    images = {}
    for name, settings in (("3dgs", train.Recipe()),
                           ("gsplat", train.Recipe(convention="gsplat")),
                           ("antialiased", train.Recipe(antialiased=True))):
        (image,), _ = S.render_views(pool, [cam], jnp.ones(3), "tiles", 64, settings.raster)
        want, _, _ = oracle.composite(g, cam, np.ones(3), cap=ALPHA_CAP[settings.convention],
                                      inclusive=STOP_INCLUSIVE[settings.convention],
                                      antialiased=settings.antialiased)
        np.testing.assert_allclose(image, np.clip(want, 0, 1), rtol=0, atol=F64_ATOL)
        if name == "3dgs":
            want = lgs_jax.render(g, cam, background=jnp.ones(3), backend="tiles", capacity=64)
            np.testing.assert_array_equal(image, np.clip(np.asarray(want.image), 0, 1))
        images[name] = image
    # SH DC 0 is grey 0.5: 0.5·cap + 1·(1 − cap)
    np.testing.assert_allclose([images["3dgs"][8, 8, 0], images["gsplat"][8, 8, 0]],
                               [0.505, 0.5005], atol=1e-5)
    small = lambda image: image[2, 2, 0] - images["3dgs"][8, 8, 0]  # above the grey
    assert 0 < small(images["antialiased"]) < 0.5 * small(images["3dgs"])


C, R = train.FitConfig, train.Recipe


@pytest.mark.parametrize("make,match", [
    (lambda: C("d", "o", steps=-1), "steps: expected an int >= 0"),
    (lambda: C("d", "o", max_gaussians=0), "max_gaussians"),
    (lambda: R(convention="inria"), "convention: expected one of"),
    (lambda: R(ssim_padding="full"), "ssim_padding"),
    (lambda: C("d", "o", pair_headroom=0.9), "pair_headroom: expected a number >= 1"),
    (lambda: C("d", "o", pair_headroom=float("nan")), "pair_headroom: expected a finite"),
    (lambda: C("d", "o", row_headroom=0.5), "row_headroom: expected a number >= 1"),
    (lambda: C("d", "o", row_headroom=float("nan")), "row_headroom"),
    (lambda: C("d", "o", stream_images=1), "stream_images: expected a bool, got 1"),
    (lambda: R(antialiased=None), "antialiased: expected a bool, got None"),
    (lambda: C("d", "o", seed=-1), "seed: expected an int >= 0"),
    (lambda: C("d", "o", crop=(1, 2)), "crop: expected a tuple"),
    (lambda: C("d", "o", compile_ahead="threads"), "compile_ahead: expected one of"),
    (lambda: C("d", "o", resume=True, overwrite=True), "resume, overwrite: they exclude"),
    (lambda: train.MCMCStrategy(cap_max=0), "strategy.cap_max: expected an int >= 1"),
    (lambda: C("d", "o", strategy="mcmc"), "strategy: expected a Strategy, got str"),
    (lambda: C("d", "o", devices=0), "devices: expected an int >= 1"),
    (lambda: C("d", "o", devices=True), "devices: expected an int, got True"),
    (lambda: C("d", "o", devices=2, recipe=R(batch=3)), "devices: 2 devices split "
                                                        "recipe.batch = 3 views unevenly")])
def test_bad_configurations_are_refused(make, match):
    with pytest.raises(ValueError, match=match):
        make()


@pytest.mark.parametrize("kwargs,match", [
    (dict(watch=3), "watch: expected None or a callable, got int"),
    (dict(watch_every=float("nan")), "watch_every: expected seconds >= 0, got nan")])
def test_fit_refuses_bad_arguments(tmp_path, kwargs, match):
    config = train.FitConfig(data="unused", out=str(tmp_path), **kwargs.pop("config", {}))
    with pytest.raises(ValueError, match=match):
        train.fit(config, **kwargs)
    with pytest.raises(ValueError, match="config: expected a FitConfig"):
        train.fit("unused")


def test_fit_usage_errors_exit_2(tmp_path, capsys):
    assert cli.main(["fit", "--data", str(tmp_path / "none"), "--steps", "1", "--out",
                     str(tmp_path / "o")]) == 2
    assert "--data" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        cli.main(["fit", "--data", str(tmp_path), "--steps", "1", "--out", str(tmp_path),
                  "--resume", "--overwrite"])
    assert exit_.value.code == 2
    for flag, values in (("--pair-headroom", ("0.5", "inf", "x")),
                         ("--row-headroom", ("0.5", "inf", "x"))):
        for value in values:
            with pytest.raises(SystemExit) as exit_:
                cli.main(["fit", "--data", str(tmp_path), "--steps", "1", "--out",
                          str(tmp_path), flag, value])
            assert exit_.value.code == 2
            assert flag in capsys.readouterr().err


@pytest.mark.slow
def test_rows_sized_to_the_walked_pairs_change_no_bit(skull, tmp_path, monkeypatch):
    """Training with the Pallas backward (interpret mode on a CPU) and its rows sized to the
    walked pairs (`FitConfig.row_headroom`), once started at one row (as if the first view
    walked one pair): the first step overflows them, they grow and the step runs again, and
    the run ends with the same bits as the run whose rows never overflowed."""
    from lgs_jax.train import state

    real, sums = state.start_rows, {}
    for grown in (False, True):
        monkeypatch.setattr(state, "start_rows", (lambda *args: 1) if grown else real)
        logs, out = [], tmp_path / str(grown)
        config = dataclasses.replace(_config(skull, out), steps=6, backend="pallas")
        train.fit(config, skull, log=logs.append)
        z = np.load(out / "checkpoint.npz")
        sums[grown] = {k: z[k] for k in z.files}
        assert json.loads((out / "checkpoint.json").read_text())["rows"] > 1
        grew = [line for line in logs if "step 1: backward rows grown to" in line]
        assert len(grew) == grown, logs
    for k, v in sums[False].items():
        np.testing.assert_array_equal(sums[True][k], v, err_msg=k)


def test_progress_bar_redraws_while_a_step_runs():
    """Step, loss, PSNR, Gaussians, rate and ETA; redrawn by the timer without any step
    finishing."""
    stream = io.StringIO()
    bar = report.Progress(0, 10, file=stream, interval=0.05)
    time.sleep(0.5)
    assert stream.getvalue().count("compiling the first step") >= 4
    bar.step(0.25, 20.0, 100)
    bar.step(0.125, 21.5, 120)
    bar.close()
    last = stream.getvalue().split("\r")[-1]
    assert "2/10" in last and "loss=0.1250" in last and "<" in last and "step/s" in last
    assert "psnr=21.50" in last and "gaussians=120" in last


def test_metrics_cut_short_by_a_kill_read_without_their_last_line(tmp_path):
    path = tmp_path / "metrics.jsonl"
    path.write_text('{"step": 1}\n{"step": 2}\n{"st')
    assert report.read_metrics(str(path)) == [{"step": 1}, {"step": 2}]
    path.write_text('{"step": 1}\n{"st\n{"step": 2}\n')
    with pytest.raises(ValueError, match="metrics.jsonl: line 2 is not JSON"):
        report.read_metrics(str(path))


def _span(part: str, start: float, end: float) -> None:
    """A compile event of JAX's (`report.COMPILE_EVENTS`) timing `part` from start to end."""
    event = {v: k for k, v in report.COMPILE_EVENTS.items()}[part]
    jax.monitoring.record_event_time_span(event, start, end, fun_name="f")


def test_compile_clock_splits_the_loop_threads_compiles_by_part():
    """Inside `with clock:` in its thread, each instant once, for the innermost event (a trace
    within a trace, a compile within a trace: constants evaluated while tracing); outside the
    blocks nothing; another thread's events are compiles ahead; a real jit's first call is a
    program compiled or loaded, and its parts are the clock's."""
    clock = report.CompileClock()
    with clock.listening():
        with clock:
            _span("trace", 11.0, 12.0)  # nested in the next: events end inner first
            _span("backend", 12.5, 13.0)
            _span("trace", 10.0, 14.0)
            _span("lower", 14.0, 15.5)
            _span("backend", 15.5, 18.0)
        _span("trace", 20.0, 30.0)  # between steps: not the steps' compile
        worker = threading.Thread(target=lambda: (_span("trace", 40.0, 42.0),
                                                  _span("backend", 41.0, 45.0)))
        worker.start()
        worker.join()
        assert clock.parts == dict(trace=3.5, lower=1.5, backend=3.0, waited=0.0)
        assert clock.seconds == 8.0 and clock.ahead_seconds == 5.0
        assert clock.programs == dict(compiled=2, loaded=0)
        x = jnp.arange(5.0)
        with clock:
            clock.waited(0.25)
            jax.jit(lambda x: x * 3 + 1)(x)  # a new function: traced
    assert sum(clock.programs.values()) == 3  # by XLA or from the persistent cache
    parts = clock.parts
    assert parts["waited"] == pytest.approx(0.25) and parts["trace"] > 3.5
    assert parts["lower"] > 1.5 and parts["backend"] > 3.0
    result = clock.result()
    assert result["compile_parts"] == parts and result["compile_seconds"] == clock.seconds
    assert result["programs_compiled"] + result["programs_loaded"] == 3
    assert result["ahead_compile_seconds"] == 5.0


def test_progress_rate_and_eta_leave_out_the_compile():
    """After a first step that compiled for a while, the rate and ETA are the steps' own (the
    loop's `rate`), not the compile's spread over the steps to come."""
    stream = io.StringIO()
    bar = report.Progress(0, 100, file=stream, interval=10)
    time.sleep(0.3)  # compiling
    bar.step(0.25, 20.0, 100, rate=50.0)
    bar.bar.refresh()
    bar.close()
    last = stream.getvalue().split("\r")[-1]
    assert "1/100" in last and "<00:01" in last and "50.00step/s" in last, last


def test_random_starts_scale_with_the_images(tmp_path):
    """Without SfM points, a point per 4 pixels of the largest training image (at most
    100,000): 50x50 images start with 625 (a CPU step at 100,000 takes far longer)."""
    from lgs_jax.train import feed, init

    config = train.FitConfig(data=tiny_capture(tmp_path / "d", size=50), out="o")
    assert [config.start_points(p) for p in (2500, 200 * 200, 800 * 800)] == [625, 10_000,
                                                                            100_000]
    assert dataclasses.replace(config, init_points=7).start_points(2500) == 7
    lines = []
    g = init.start_gaussians(feed.prepare(config.data), config, lines.append)
    assert g.num == 625 and lines == ["no SfM points: 625 random points in a cube of "
                                      "half-width 0.25 x scene scale"]


@pytest.mark.slow  # CI time: a whole fit for one image dtype
def test_8_bit_images_train_to_the_same_bits(tmp_path):
    """A capture at full size without alpha or distortion: its images held as uint8
    (`load_dataset(dtype=np.uint8)`, `fit --uint8-images`) train to the float32 run's bits,
    streamed or not; the held-out score is the same."""
    from PIL import Image

    data = tmp_path / "data"
    (data / "train").mkdir(parents=True)
    rng = np.random.default_rng(0)
    frames = []
    for i in range(4):
        Image.fromarray(rng.integers(0, 256, (16, 16, 3), np.uint8)).save(
            data / "train" / f"r_{i}.png")
        pose = np.eye(4)
        pose[:3, 3] = [0.1 * i, 0.0, 3.0]  # Blender axes: the camera looks down -z at 0
        frames.append(dict(file_path=f"./train/r_{i}", transform_matrix=pose.tolist()))
    (data / "transforms_train.json").write_text(json.dumps(dict(camera_angle_x=0.7,
                                                                frames=frames)))
    results = {}
    for name, uint8, stream in (("f32", False, None), ("u8", True, None), ("u8s", True, True)):
        config = train.FitConfig(data=str(data), out=str(tmp_path / name), steps=4,
                                 backend="reference", eval_every=100, init_points=64,
                                 checkpoint_every=100, uint8_images=uint8, stream_images=stream)
        results[name] = train.fit(config, log=lambda m: None)
    a = np.load(tmp_path / "f32" / "checkpoint.npz")
    for name in ("u8", "u8s"):
        b = np.load(tmp_path / name / "checkpoint.npz")
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name} {key}")
        assert results[name]["heldout_psnr"] == results["f32"]["heldout_psnr"]


def _two_views(tmp_path):
    """A capture of two 8x8 views (too few to hold one out); returns its folder."""
    import matplotlib.image

    data = tmp_path / "data"
    (data / "train").mkdir(parents=True)
    frames = []
    for i in (1, 2):
        matplotlib.image.imsave(data / "train" / f"r_{i}.png", np.zeros((8, 8, 4)))
        frames.append(dict(file_path=f"./train/r_{i}", transform_matrix=np.eye(4).tolist()))
    (data / "transforms_train.json").write_text(json.dumps(dict(camera_angle_x=0.7,
                                                                frames=frames)))
    return data


def test_fit_needs_held_out_views(tmp_path):
    data = _two_views(tmp_path)
    with pytest.raises(ValueError, match="needs training views and held-out views"):
        train.fit(train.FitConfig(data=str(data), out=str(tmp_path / "out"), steps=1))


# CI time (a step's compile): the default set checks a fit on every view in
# tests/parallel/test_gaussian_parallel_training.py, whose runs train on every view
@pytest.mark.slow
def test_a_fit_on_every_view_evaluates_nothing(tmp_path):
    """A capture too small to hold a view out trains on every view (`train_on_all`): nothing
    is evaluated, though an evaluation is due after every step."""
    data = _two_views(tmp_path)
    lines = []
    result = train.fit(train.FitConfig(data=str(data), out=str(tmp_path / "all"), steps=2,
                                       backend="reference", train_on_all=True, eval_every=1,
                                       init_points=50), log=lines.append)
    assert result["heldout_psnr"] is None and result["heldout_ssim"] is None
    assert any("no held-out views to evaluate" in m for m in lines), lines
    rows = report.read_metrics(str(tmp_path / "all" / "metrics.jsonl"))
    assert [r["step"] for r in rows] == [1, 2] and all("heldout_psnr" not in r for r in rows)
    assert not [n for n in os.listdir(tmp_path / "all") if n.startswith("heldout_")]


@pytest.mark.slow  # CI time: the benchmark's own run, a whole fit
def test_gsplat_comparison_runs_ours_without_gsplat(data_dir, tmp_path, capsys):
    """benchmarks/train_vs_gsplat.py's own parts on the CPU: ours at 0 steps (no compile of a
    training step), its CSVs, and the comparison table from a stand-in gsplat result."""
    from benchmarks import train_vs_gsplat as bench

    if not os.path.isdir(os.path.join(data_dir, "skull")):
        pytest.skip("skull not found")
    out = str(tmp_path / "bench")
    assert bench.main(["--data-root", data_dir, "--scenes", "skull", "--downscale", "32",
                       "--cap", "300", "--steps", "0", "--no-gsplat", "--inline",
                       "--out", out]) == 0
    row = next(csv.DictReader(open(os.path.join(out, "summary.csv"))))
    assert row["scene"] == "skull" and row["trainer"] == "lgs_jax" and row["gaussians"] == "300"
    assert row["package"] == os.path.dirname(os.path.dirname(os.path.abspath(lgs_jax.__file__)))
    assert float(row["final_psnr"]) > 10
    ours = json.load(open(os.path.join(out, "skull_ours.json")))
    theirs = dict(ours, trainer="gsplat", ms_per_step=2.0, peak_mb=100.0,
                  curve=[dict(c, psnr=c["psnr"] - 0.5) for c in ours["curve"]])
    ours.update(ms_per_step=5.0, ms_per_step_excl_compile=4.0, peak_mb=150.0)
    bench.print_table([ours, theirs])
    assert "PSNR +0.50 dB, SSIM +0.0000, time per step x2.00, peak memory x1.50" in \
        capsys.readouterr().out
    args = bench.parse(["--data-root", data_dir, "--downscale", "32", "--refine-from", "7"])
    assert bench.scene_setup(args, "skull")[1].strategy.refine_start_iter == 7  # gsplat's too


def test_gsplat_comparison_workers_import_the_package_their_parent_would(tmp_path):
    """An A/B of two versions (`PYTHONPATH=TREE python benchmarks/train_vs_gsplat.py`) must run
    TREE's lgs_jax in the worker processes too: `package_root` is the folder of the lgs_jax
    first on the path, which the workers' PYTHONPATH puts first (it used to put this
    repository first, so both arms of an A/B ran this tree)."""
    tree = tmp_path / "tree"
    (tree / "lgs_jax").mkdir(parents=True)
    (tree / "lgs_jax" / "__init__.py").write_text("")
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    code = "from benchmarks.train_vs_gsplat import package_root; print(package_root())"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree), root]))
    out = subprocess.run([sys.executable, "-P", "-c", code], env=env, cwd=str(tmp_path),
                         capture_output=True, text=True, check=True).stdout
    assert out.strip() == str(tree)


def test_seed_summary_pairs_the_trainers_by_step(tmp_path, capsys):
    """benchmarks/seed_summary.py: ours − gsplat's per run (last step, curve mean from a step),
    and the mean with its standard error over runs."""
    from benchmarks import seed_summary

    def write(name, ours, theirs):
        path = tmp_path / name
        with open(path, "w") as f:
            f.write("scene,trainer,step,heldout_psnr,heldout_ssim,gaussians\n")
            for trainer, curve in (("lgs_jax", ours), ("gsplat", theirs)):
                f.writelines(f"skull,{trainer},{s},{p},{q},10\n" for s, (p, q) in curve.items())
        return str(path)

    a = write("a.csv", {500: (20, 0.5), 1000: (22, 0.7), 1500: (24, 0.8)},
              {500: (30, 0.9), 1000: (21, 0.6), 1500: (25, 0.9), 2000: (26, 0.95)})
    b = write("b.csv", {1000: (23, 0.8), 1500: (25, 0.85)}, {1000: (22, 0.8), 1500: (24, 0.8)})
    d = seed_summary.differences(a, "skull", from_step=1000)  # step 2000: gsplat's alone
    assert d["final_psnr"] == -1 and abs(d["final_ssim"] + 0.1) < 1e-12
    assert d["curve_psnr"] == 0 and abs(d["curve_ssim"]) < 1e-12
    assert seed_summary.mean_and_error([1.0, 3.0]) == (2.0, 1.0)
    assert seed_summary.mean_and_error([1.0])[1] is None
    assert seed_summary.main([a, b, "--from-step", "1000"]) == 0
    assert "final_psnr +0.0000 ± 1.0000" in capsys.readouterr().out
    with pytest.raises(ValueError, match="no step evaluated by both"):
        seed_summary.differences(a, "lego")


def test_resume_refuses_other_settings_and_old_checkpoints(tmp_path):
    from lgs_jax.train import checkpoint

    config = train.FitConfig(data="d", out="o", strategy=train.MCMCStrategy())
    saved = checkpoint.config_of(config)
    assert checkpoint.config_mismatch(saved, json.loads(json.dumps(saved))) is None
    other = checkpoint.config_of(dataclasses.replace(
        config, steps=5, backend="pallas", pair_headroom=1.5, row_headroom=2.0, eval_every=3,
        checkpoint_every=4, init_points=9, stream_images=True, compile_ahead="off"))
    # run length, backend, periods, headrooms, streaming, the start may change
    assert checkpoint.config_mismatch(saved, other) is None
    changed = checkpoint.config_of(
        dataclasses.replace(config, strategy=train.MCMCStrategy(cap_max=7), seed=1))
    problem = checkpoint.config_mismatch(saved, changed)
    assert "strategy_settings.cap_max: 1000000 -> 7" in problem and "seed: 0 -> 1" in problem
    # a setting the checkpoint predates counts as its default; one it has that this version
    # lacks (init_points, in settings before) is not compared
    defaults = checkpoint.default_config(config)
    older = json.loads(json.dumps(saved))
    del older["settings"]["color_opt"], older["strategy_settings"]["cap_max"]
    del older["settings"]["name"]
    older["settings"].update(init_points=100_000, init_extent=None)
    assert checkpoint.config_mismatch(older, saved) is not None
    assert checkpoint.config_mismatch(older, saved, defaults) is None
    colour = checkpoint.config_of(dataclasses.replace(
        config, recipe=train.Recipe(color_opt=True)))
    assert "settings.color_opt: False -> True" in checkpoint.config_mismatch(older, colour,
                                                                             defaults)
    (tmp_path / "checkpoint.json").write_text(json.dumps(dict(step=3, capacity=8)))
    with pytest.raises(ValueError, match="older lgs_jax.train"):
        checkpoint.read_meta(str(tmp_path))


def test_sized_rows_start_at_the_first_views_pairs(skull, tmp_path):
    """`FitConfig.row_headroom`: a run's rows start at those of its pair capacity
    (`ahead.Sizes.rows_for`: headroom times the first training view's pairs, among which are
    the walked pairs) where the backend stores
    gradient rows (the Pallas backends), at `config.ROW_HEADROOM` where it is None; a backend
    without rows, or Gaussian parallel by default: no rows (a row per pair slot)."""
    from lgs_jax.train import config as C, state

    rd = train_data.prepare(skull, 1, None)
    first = jax.tree.map(lambda x: x[0], rd.train_cams)
    for h, backend, want in ((None, "pallas", C.ROW_HEADROOM), (2.0, "tiles", None),
                             (2.0, "pallas", 2.0)):
        config = train.FitConfig(data=skull.path, out=str(tmp_path), steps=10, row_headroom=h,
                                 pool_size=1024)
        setup = train.Setup.of(config, rd.scene_scale, backend)
        st = state.fresh(config, setup, rd, lambda m: None)
        pairs = lgs_jax.count_pairs(train.render_gaussians(st.pool.params, st.pool.active), first)
        assert int(pairs) == state.pairs(st.pool, first) > 0
        assert st.capacity == lgs_jax.pair_capacity(int(pairs), config.pair_headroom)
        rows = want and ahead.Sizes(config.pair_headroom, want).rows_for(st.capacity)
        assert st.rows == rows and (rows is None or int(pairs) * want <= rows), (h, backend)
    assert C.row_headroom(train.FitConfig(data="d", out="o", gaussian_devices=2)) is None
    assert C.row_headroom(train.FitConfig(data="d", out="o", row_headroom=3.0)) == 3.0
