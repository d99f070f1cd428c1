"""Gaussian-parallel training (`fit` with gaussian_devices, lgs_jax.train.sharded): a run of
two views per step stopped on one device and resumed on a 2 x 2 mesh of simulated CPU devices
(devices=2 rows, each splitting the Gaussians over gaussian_devices=2 and rendering one of the
step's views), with buffers that overflow and grow, gives the scene of the same run on one
device within the stated bound (the forward is the same bits, so the first resumed step's
loss is within the rounding of its sums; the gradients' sums, over tiles and over the rows'
views, are re-associated and Adam carries the difference at most a learning rate per step); its
refinements decide the same (the same counts at every step) and keep the blocks balanced by work
(their Gaussians' projections and tile pairs in a few training views: `sharded_state.work`; a
refinement on 4 devices is the one-device refinement's bits, both strategies); each run writes
one checkpoint and one scene.ply; trained on every view, with an evaluation due after every
step, the runs evaluate nothing (the default set's check of a fit without held-out views:
test_train.py's own such fit is in the slow set). The slow set runs the whole run (one view
per step) on 2 and on 4 devices (the first step's loss, held-out views rendered sharded), and
MCMC with the views' own parameters on 2 devices and on a 2 x 2 mesh. A mesh needing more
devices than there are, or a batch its rows split unevenly, is refused by field name.

The runs happen in one child process (tests/parallel/training_child.py: JAX simulates 4
devices only when told before it starts); the test here checks their folders."""

import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax.io.ply import load_ply
from lgs_jax.train import DefaultStrategy, FitConfig, Pool, Recipe, fit, ops, sharded

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# the child's (importing it would start its JAX with 4 devices)
STEPS, HALF, PIXELS = 8, 4, 32 * 64 * 3
BATCH = dict(fast=2, slow=1)  # views per step


def _run_child(tmp_path, part: str) -> dict:
    """The child's runs of `part` under tmp_path; returns their logs."""
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT)
    done = subprocess.run([sys.executable, "-m", "tests.parallel.training_child", str(tmp_path),
                           part], env=env, cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.load(open(tmp_path / "logs.json"))


def _rows(run) -> list[dict]:
    return [json.loads(line) for line in open(run / "metrics.jsonl")]


def ply_fields(path) -> dict:
    """A scene.ply's parameters by `sharded.drift_bound`'s groups."""
    g = load_ply(str(path))
    return dict(means=g.means, quats=g.quats, log_scales=g.log_scales,
                logit_opacities=g.logit_opacities, sh_dc=g.sh[:, :1], sh_rest=g.sh[:, 1:])


def beyond(one: dict, got: dict, bound: dict, u: float, pairs: bool = False,
           steps: int = STEPS):
    """Which Gaussians of `one` differ from those of `got` (`ply_fields`) in some parameter by
    more than `bound` plus the rounding of `steps` updates: (N,) bool, row against row, or
    with `pairs` (N, M) bool, every row of `one` against every row of `got`."""
    far = False
    for k, x in one.items():
        x, y = (x[:, None], got[k][None]) if pairs else (x, got[k])
        err = np.abs(x.astype(np.float64) - y)
        slack = 2 * steps * u * np.maximum(np.abs(x), np.abs(y))
        far = far | np.any(err > bound[k] + slack, axis=tuple(range(2 if pairs else 1,
                                                                    err.ndim)))
    return far


def _same_scene(tmp_path, logs, runs, batch: int):
    """Every sharded run's scene.ply against the one-device run's: the same Gaussians (the
    refinements decided the same at every step), each parameter within `sharded.drift_bound`
    plus the rounding of the updates. Clones fill free slots in the order of their gradients
    (`ops.allocate`), so two whose gradients are within rounding of each other may trade slots:
    the Gaussians beyond the bound in place must pair off within it. The run's first step (from
    the start, or from the one-device run's checkpoint) has the one-device run's loss at that
    step within the rounding of its sums (the images are the same bits: γ_n·(ℓ + 1), n the
    values summed over the `batch` views, the SSIM map's values at most 1)."""
    scale = float(logs["d1"][0].split("scene scale ")[1]) + 5e-4  # logged to 3 decimals
    bound = sharded.drift_bound(Recipe(batch=batch), STEPS, scale)
    u = np.finfo(np.float32).eps / 2
    one, one_rows = ply_fields(tmp_path / "d1" / "scene.ply"), _rows(tmp_path / "d1")
    counts = lambda rows: [(r["step"], r["gaussians"]) for r in rows if "loss" in r]
    n = batch * PIXELS
    loss = lambda rows, step: [r["loss"] for r in rows if "loss" in r and r["step"] == step][-1]
    for run in runs:
        rows = _rows(tmp_path / run)  # a resumed run's: the checkpoint's rows first
        assert counts(rows) == counts(one_rows)[-len(counts(rows)):], run
        first = HALF + 1 if logs[run][0].startswith(f"resumed at step {HALF} ") else 1
        a, b = loss(one_rows, first), loss(rows, first)
        assert abs(a - b) <= n * u / (1 - n * u) * (a + 1), (run, first, a, b)
        got = ply_fields(tmp_path / run / "scene.ply")
        assert all(x.shape == got[k].shape for k, x in one.items()), run
        moved = np.flatnonzero(beyond(one, got, bound, u))
        assert len(moved) <= len(one["means"]) // 50, (run, moved)  # traded slots are rare
        pick = lambda f: {k: x[moved] for k, x in f.items()}
        close = ~beyond(pick(one), pick(got), bound, u, pairs=True)
        assert close.any(axis=0).all() and close.any(axis=1).all(), (run, moved)


def _even_work(r: dict, block: int | None = None) -> bool:
    """A refinement report's blocks hold their active Gaussians' work in equal shares, each
    within the heaviest Gaussian's work of its share (a full block of `block` slots excepted),
    and not all in one block."""
    work, per = r["per_device_work"], r["per_device"]
    share = sum(work) / len(work)
    full = block is not None and max(per) == block
    return (full or max(work) <= share + r["heaviest"] * (1 + 1e-6)) and min(per) > 0


def _balanced(tmp_path, runs, refinements: int):
    """After every refinement of the sharded `runs` the devices' blocks hold equal shares of
    the work (`_even_work`), the uneven ones too (301 Gaussians at the start). Rows without
    `per_device` are a one-device run's, before a resume."""
    seen = 0
    for run in runs:
        for r in _rows(tmp_path / run):
            if "per_device" in r:
                assert sum(r["per_device"]) == r["gaussians"] and _even_work(r), (run, r)
                seen += 1
    assert seen == refinements


def _refined_alike(logs):
    """A refinement of each strategy on 4 devices, back in slot order, is the one-device
    refinement's bits, its blocks balanced."""
    for name, r in logs["refinements"].items():
        assert all(r["same"]) and len(r["same"]) > 10, (name, r["same"])
        per = r["per_device"]
        assert sum(per) == r["after"] != r["before"] and _even_work(r), (name, r)


def _resumed(tmp_path, logs):
    """The one-device run stopped after step HALF (its checkpoint) resumes on a 2 x 2 mesh with
    its buffers sized at its first view's needs exactly (training_child.py): the exchange
    overflows, and the pairs it could not deliver are counted, so both buffers grow at once
    (one recompile; the result is checked in `_same_scene`).
    One scene.ply per run."""
    before = [r["gaussians"] for r in _rows(tmp_path / "d1") if r.get("step") == HALF][0]
    assert f"resumed at step {HALF} ({before} Gaussians)" in logs["d1"], logs["d1"]
    resumed = logs["d1_resumed_on_2x2"]
    assert resumed[0] == f"resumed at step {HALF} ({before} Gaussians)", resumed
    grown = [line for line in resumed if "grown to" in line]
    assert len(grown) == 1 and "pair capacity grown to" in grown[0] and (
        "exchange capacity grown to" in grown[0]), resumed  # both at once: one recompile
    for run, devices in (("d1", (1, 1)), ("d1_resumed_on_2x2", (2, 2))):
        result = json.load(open(tmp_path / run / "result.json"))
        assert (result["devices"], result["gaussian_devices"]) == devices
        assert [f for f in os.listdir(tmp_path / run) if f.endswith(".ply")] == ["scene.ply"]
        assert load_ply(str(tmp_path / run / "scene.ply")).num == result["gaussians"]


def _evaluated_nothing(tmp_path, logs, runs):
    """Runs on every view (`FitConfig.train_on_all`, nothing held out), an evaluation due after
    every step: none is made, nor an image of one, and the result's scores are None, as the
    log says."""
    for run in runs:
        result = json.load(open(tmp_path / run / "result.json"))
        assert result["heldout_psnr"] is None and result["heldout_ssim"] is None, run
        assert f"step {STEPS}: no held-out views to evaluate (trained on every view)" in \
            logs[run], logs[run]
        assert not [r for r in _rows(tmp_path / run) if "heldout_psnr" in r], run
        assert not [f for f in os.listdir(tmp_path / run) if f.startswith("heldout_")], run


def test_gaussian_parallel_training(tmp_path):
    logs = _run_child(tmp_path, "fast")
    _same_scene(tmp_path, logs, ["d1_resumed_on_2x2"], BATCH["fast"])
    _balanced(tmp_path, ["d1_resumed_on_2x2"], 1)  # the refinement at step 6
    _refined_alike(logs)
    _resumed(tmp_path, logs)
    _evaluated_nothing(tmp_path, logs, ["d1", "d1_resumed_on_2x2"])


@pytest.mark.slow
def test_gaussian_parallel_training_on_two_and_four_devices(tmp_path):
    logs = _run_child(tmp_path, "slow")
    _same_scene(tmp_path, logs, ["d2", "d4"], BATCH["slow"])
    mcmc = ["mcmc_views_d2", "mcmc_views_2x2"]
    _balanced(tmp_path, ["d2", "d4", *mcmc], 8)
    # MCMC with the views' poses, colours and bilateral grids on 2 devices and on a 2 x 2 mesh
    # (two views per step): n + n // 20 at each refinement, every step applied
    for run in mcmc:
        rows = [r for r in _rows(tmp_path / run) if "loss" in r]
        assert [r["gaussians"] for r in rows] == [301] * 3 + [316] * 3 + [331] * 2, run
        assert all(np.isfinite(r["loss"]) for r in rows), run
        result = json.load(open(tmp_path / run / "result.json"))
        assert result["skipped_steps"] == 0 and np.isfinite(result["heldout_psnr"]), run
    assert (tmp_path / "mcmc_views_2x2" / "heldout_v0.png").exists()
    # the held-out view rendered sharded (`sharded_state.Evaluations`) and saved
    psnr = [json.load(open(tmp_path / run / "result.json"))["heldout_psnr"]
            for run in ("d1", "d2", "d4")]
    assert np.allclose(psnr, psnr[0], rtol=1e-3, atol=0), psnr
    assert all((tmp_path / run / "heldout_v0.png").exists() for run in ("d2", "d4"))


def test_gaussian_parallel_refused_combinations(tmp_path, monkeypatch):
    base = dict(data=str(tmp_path), out=str(tmp_path / "run"), gaussian_devices=2)
    for extra, field in ((dict(recipe=Recipe(app_opt=True)), "recipe.app_opt"),
                         (dict(row_headroom=2.0), "row_headroom"),
                         (dict(compile_ahead="thread"), "compile_ahead")):
        with pytest.raises(ValueError, match=f"^{field}: not with gaussian_devices = 2"):
            FitConfig(**base, **extra)
    with pytest.raises(ValueError, match="^gaussian_devices: expected an int from 1 to 1"):
        fit(FitConfig(**base, strategy=DefaultStrategy()))  # one CPU device here
    # a mesh of views x Gaussians: its rows split the batch evenly, its devices are there
    FitConfig(**base, devices=2, recipe=Recipe(batch=4))
    with pytest.raises(ValueError, match="^devices: 2 devices split recipe.batch = 3 views "
                                         "unevenly"):
        FitConfig(**base, devices=2, recipe=Recipe(batch=3))
    monkeypatch.setattr(jax, "devices", lambda *_: [None] * 3)  # 3 of them, each <= 3
    with pytest.raises(ValueError, match=r"^devices, gaussian_devices: a mesh of 2 x 2 needs 4 "
                                         r"devices; there are 3 cpu devices here"):
        fit(FitConfig(**base, devices=2, recipe=Recipe(batch=2), strategy=DefaultStrategy()))


def test_gaussian_parallel_noise_drawn_per_slot():
    # MCMC's noise on the means: a pool stored in another row order (row j holds slot
    # order[j]) draws for each slot what the pool in slot order draws
    rng = np.random.default_rng(0)
    n = 12
    params = dict(means=rng.normal(size=(n, 3)), quats=rng.normal(size=(n, 4)),
                  log_scales=rng.normal(-1, 0.3, (n, 3)), logit_opacities=rng.normal(-3, 1, n))
    pool = Pool({k: jnp.asarray(v, jnp.float32) for k, v in params.items()},
                jnp.asarray(rng.uniform(size=n) < 0.7))
    order = jnp.asarray(rng.permutation(n), jnp.int32)
    key = jax.random.key(3)
    whole = ops.inject_noise(pool, key, 0.1)
    stored = ops.inject_noise(jax.tree.map(lambda x: x[order], pool), key, 0.1, slots=order)
    np.testing.assert_array_equal(stored.params["means"], whole.params["means"][order])
