"""The fast recipe (`fit --recipe fast`): its image levels (factors, first steps, block means,
scaled cameras against a full render), the budget strategy (its curve, its pool, the relocation
of unseen Gaussians), the training-loss early stop (flat against falling losses, held-out rows
ignored, a resumed run's losses), the recipes' values (explicit fields win, the default recipe
unchanged), the command line, and a tiny whole fit on the CPU: twice the same bits, and a resumed
run the bits of an uninterrupted one."""

import dataclasses
import functools
import json
import math
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lgs_jax
from lgs_jax import cli, train
from lgs_jax.cli import fit as fit_cmd
from lgs_jax.synthetic import random_scene, synthetic_camera
from lgs_jax.train import ahead, budget, checkpoint, early_stop, levels, optim, recipes, report
from lgs_jax.train import pool as P
from lgs_jax.train.strategy import StepInfo

from .captures import tiny_capture


# --- levels ------------------------------------------------------------------------------------

def test_levels_halve_the_size_per_level_from_fixed_steps():
    assert levels.factors(1) == (1,) and levels.factors(3) == (4, 2, 1)
    assert levels.starts(1, 4000, 0.5) == (0,)
    assert levels.starts(3, 4000, 0.5) == (0, 1000, 2000)
    assert levels.starts(2, 10, 0.25) == (0, 2)
    first = levels.starts(3, 4000, 0.5)
    assert [levels.level_at(s, first) for s in (0, 999, 1000, 1999, 2000, 3999)] == [
        0, 0, 1, 1, 2, 2]
    assert levels.level_at(0, levels.starts(3, 100, 0.0)) == 2  # full resolution throughout
    levels.check([(16, 12), (8, 8)], 4)
    with pytest.raises(ValueError, match="recipe.levels: 4 levels downscale the 7x9"):
        levels.check([(16, 12), (7, 9)], 4)


@pytest.mark.parametrize("k", [2, 3, 4])
def test_a_level_image_is_the_float64_block_mean(k):
    """Each k x k block's mean in float64, rounded once to float32 (8-bit: to the nearest
    8-bit value); the last 13 % k rows and 10 % k columns dropped, as `load_dataset` does."""
    rng = np.random.default_rng(k)
    image = rng.uniform(0, 1, (13, 10, 3)).astype(np.float32)
    h, w = 13 // k, 10 // k
    want = np.empty((h, w, 3))
    for i in range(h):
        for j in range(w):
            block = image[i * k:(i + 1) * k, j * k:(j + 1) * k].astype(np.float64)
            want[i, j] = [math.fsum(block[..., c].ravel()) / k**2 for c in range(3)]
    got = levels.downscaled(image, k)
    assert got.dtype == np.float32 and got.shape == (h, w, 3)
    np.testing.assert_array_equal(got, want.astype(np.float32))
    eight = np.round(image * 255).astype(np.uint8)
    got8 = levels.downscaled(eight, k)
    mean8 = eight[:h * k, :w * k].reshape(h, k, w, k, 3).astype(np.float64).mean((1, 3))
    assert got8.dtype == np.uint8
    np.testing.assert_array_equal(got8, np.round(mean8))
    assert levels.downscaled(image, 1) is image


def test_a_coarse_level_renders_the_block_mean_of_the_full_render():
    """Intrinsics divided by k: the render at 1/k size matches the k x k block means of the
    full-size render (mean error below 0.009 on smooth Gaussians); the principal point a
    quarter of a coarse pixel off, or at the pixel corner, misses it."""
    g = random_scene(60, seed=3)
    g = dataclasses.replace(g, log_scales=g.log_scales + np.float32(1.5))  # smooth, no aliasing
    cam, k = synthetic_camera(96, 64), 4
    # a pair buffer for every pair 60 Gaussians can have on 6 x 4 tiles: no pair count compiled
    render = lambda c: np.asarray(lgs_jax.render(g, c, backend="reference", capacity=60 * 24)
                                  .image, np.float64)
    block = levels.downscaled(render(cam), k)
    coarse = levels.scaled_cameras(cam, k)
    assert (coarse.width, coarse.height) == (24, 16)
    err = lambda c: float(np.mean(np.abs(render(c) - block)))
    assert err(coarse) < 0.009 < err(dataclasses.replace(coarse, cx=coarse.cx + 0.25))
    assert 0.009 < err(dataclasses.replace(coarse, cx=coarse.cx + 0.5, cy=coarse.cy + 0.5))


# --- the budget strategy -----------------------------------------------------------------------

def test_budget_curve_rises_steepest_first_to_the_budget_at_its_step():
    c = np.asarray(budget.budget_curve(jnp.arange(3000), 1000, 20_000, 300, 2000))
    assert set(c[:301].tolist()) == {1000} and set(c[2000:].tolist()) == {20_000}
    assert np.all(np.diff(c) >= 0) and np.all(c <= 20_000)
    assert abs(int(c[1150]) - (1000 + 19_000 * 3 // 4)) <= 1  # halfway: 3/4 of the rise (float32)
    rise = np.diff(c)
    assert rise[400:500].sum() > rise[1800:1900].sum() > 0  # steepest first
    assert int(budget.budget_count(10**9, 20, 3_000_000)) == 3_000_000  # no int32 overflow


def _pool_of(g, size):
    pool = P.from_gaussians(jax.tree.map(jnp.asarray, g), size)
    return pool, optim.optimizer(train.Recipe(sh_degree=0), 100, 1.0).init(pool.params)


def test_budget_strategy_fills_its_pool_on_the_curve_and_never_beyond():
    s = train.BudgetStrategy(refine_start_iter=2, refine_every=2, refine_stop_iter=20,
                             budget=4, budget_until=10, unseen_after=0)
    assert s.max_count(25, 20, 1000) == 100 and s.max_count(25, 20, 60) == 60
    assert s.max_count(25, 3, 1000) == 25  # no refinement in the run: no room needed
    slow = dataclasses.replace(s, growth="mcmc")
    assert slow.max_count(25, 20, 1000) == train.MCMCStrategy(
        refine_start_iter=2, refine_every=2, cap_max=100).max_count(25, 20, 1000)
    pool, opt = _pool_of(random_scene(25, seed=1), s.max_count(25, 20, 1000))
    state = s.init(pool, 1.0)
    refine = jax.jit(functools.partial(s.refine, cap=1000))
    counts = {}
    for step in (x for x in range(20) if s.refine_due(x)):
        state, pool, opt, rep = refine(state, pool, opt, step, jax.random.key(step))
        counts[step] = int(jnp.sum(pool.active))
        assert int(rep["needed"]) <= int(rep["free"])
        assert counts[step] == int(budget.budget_curve(step, 25, 100, 2, 10)), step
    assert list(counts) == [4, 6, 8, 10, 12, 14, 16, 18]
    assert counts[4] > 25 and counts[10] == counts[18] == 100 == pool.size
    assert list(counts.values()) == sorted(counts.values())


def test_gaussians_no_view_sees_are_relocated_after_unseen_after_steps():
    s = train.BudgetStrategy(unseen_after=10, budget=1, noise_lr=0.0)
    g = random_scene(8, seed=2)
    g = dataclasses.replace(g, logit_opacities=np.zeros(8, np.float32))  # opacity 0.5: alive
    pool, opt = _pool_of(g, 8)
    state = s.init(pool, 1.0)
    visible = jnp.asarray(np.arange(8) < 6)[None]  # slots 6 and 7: in no view
    info = StepInfo(None, visible, 0.0, 8, 8)
    for step in range(11):
        state, pool, opt = s.step(state, pool, opt, info, step, jax.random.key(step))
    assert np.asarray(state["last_seen"]).tolist() == [10] * 6 + [0, 0]
    early = s.refine(state, pool, opt, 9, jax.random.key(0), 100)  # 9 steps unseen: kept
    assert int(early[3]["unseen"]) == 0 and int(early[3]["relocated"]) == 0
    state, new, _, rep = s.refine(state, pool, opt, 10, jax.random.key(0), 100)
    assert (int(rep["unseen"]), int(rep["relocated"]), int(rep["added"])) == (2, 2, 0)
    assert np.asarray(state["last_seen"]).tolist() == [10] * 8  # counted afresh
    means, old = np.asarray(new.params["means"]), np.asarray(pool.params["means"])
    np.testing.assert_array_equal(means[:6], old[:6])
    assert all(any(np.array_equal(m, o) for o in old[:6]) for m in means[6:])  # onto seen ones


# --- the early stop ----------------------------------------------------------------------------

W = 10
FLAT = {s: 0.1 + 1e-4 * (-1) ** s for s in range(1, 101)}
FALLING = {s: 0.1 * 0.99**s for s in range(1, 101)}  # about 10 % per window


def test_early_stop_ends_a_flat_run_not_a_falling_one():
    assert early_stop.plateaued(FLAT, 40, W, 0.002)
    assert not early_stop.plateaued(FALLING, 40, W, 0.002)
    assert early_stop.plateaued(FALLING, 40, W, 0.2)  # a fall below the least gain asked
    assert [s for s in range(101) if early_stop.is_check(s, 30, W)] == [50, 60, 70, 80, 90, 100]
    with_nan = {s: (math.nan if s == 45 else v) for s, v in FLAT.items()}  # a skipped step
    assert early_stop.plateaued(with_nan, 50, W, 0.002)
    recipe = train.Recipe(name="fast", stop_window=W)
    rule = early_stop.EarlyStop.of(recipe, 30, [dict(step=s, loss=v) for s, v in FLAT.items()])
    assert [s for s in range(1, 101) if rule.due(s)] == [50, 60, 70, 80, 90, 100]
    assert rule.means(50) == pytest.approx((0.1, 0.1), abs=2e-4)
    off = early_stop.EarlyStop.of(train.Recipe(stop_window=W), 30,
                                  [dict(step=s, loss=v) for s, v in FLAT.items()])
    assert not any(off.due(s) for s in range(1, 101))  # the default recipe: never


def test_early_stop_reads_the_training_losses_alone():
    """Held-out rows (flat scores) beside falling training losses: no stop; a resumed run
    whose metrics lost the losses a check needs is refused before any step."""
    recipe = train.Recipe(name="fast", stop_window=W)
    rows = []
    for s, v in FALLING.items():
        rows += [dict(step=s, loss=v, psnr=20.0), dict(step=s, heldout_psnr=25.0,
                                                       heldout_ssim=0.9)]
    rows += [dict(refine_step=s, relocated=0) for s in range(0, 100, 10)]
    rule = early_stop.EarlyStop.of(recipe, 30, rows)
    assert not any(rule.due(s) for s in range(1, 101))
    with pytest.raises(ValueError, match="m.jsonl: no training loss of step 41, which the "
                                         "early stop needs"):
        early_stop.EarlyStop.of(recipe, 30, rows[:80], "m.jsonl", done=60)
    early_stop.EarlyStop.of(recipe, 30, rows[:80], "m.jsonl", done=40)  # all it needs


# --- the recipes -------------------------------------------------------------------------------

def test_the_default_recipe_is_unchanged_and_the_fast_one_fills_its_fields():
    c = train.FitConfig(data="d", out="o")
    assert (c.steps, c.strategy, c.recipe.name) == (30_000, train.DefaultStrategy(), "default")
    assert (c.recipe.batch, c.recipe.levels, c.recipe.early_stop) == (1, 1, False)
    f = train.FitConfig(data="d", out="o", recipe=train.Recipe(name="fast"), max_gaussians=5000)
    assert (f.steps, f.strategy) == (2000, train.BudgetStrategy(cap_max=5000))
    assert (f.recipe.batch, f.recipe.levels, f.recipe.early_stop) == (2, 3, True)
    mine = train.FitConfig(data="d", out="o", steps=7, strategy=train.MCMCStrategy(),
                           recipe=train.Recipe(name="fast", batch=1, levels=1,
                                               early_stop=False))
    assert (mine.steps, mine.strategy) == (7, train.MCMCStrategy())
    assert (mine.recipe.batch, mine.recipe.levels, mine.recipe.early_stop) == (1, 1, False)
    assert train.Recipe(batch=4, early_stop=True).batch == 4
    # a checkpoint records the recipe: a default-recipe run does not resume a fast one
    problem = checkpoint.config_mismatch(checkpoint.config_of(f), checkpoint.config_of(
        dataclasses.replace(c, max_gaussians=5000)))
    assert "settings.name: 'fast' -> 'default'" in problem and "settings.levels: 3 -> 1" \
        in problem and "strategy: 'BudgetStrategy' -> 'DefaultStrategy'" in problem


def test_a_wide_start_takes_the_recipes_wide_start_values_where_it_filled_them():
    """The fast recipe on a wide random start: the fields it filled take WIDE_START_VALUES
    (steps 4,000, DefaultStrategy); fields given keep their values, another start or the
    default recipe changes nothing, and the capture is read only where it matters."""
    fast, said = train.Recipe(name="fast"), []
    f = train.FitConfig(data="d", out="o", recipe=fast, max_gaussians=5000)
    assert recipes.filled(f) == {"steps", "strategy"}
    got = recipes.for_start(f, lambda: True, said.append)
    assert (got.steps, got.strategy) == (4000, train.DefaultStrategy())
    assert said == ["no SfM points: the fast recipe's wide random start, steps 4000, "
                    "strategy default"]
    assert got.recipe == f.recipe and got.max_gaussians == 5000
    assert recipes.for_start(f, lambda: False, said.append) is f and len(said) == 1
    mine = train.FitConfig(data="d", out="o", recipe=fast, strategy=train.MCMCStrategy())
    assert recipes.for_start(mine, lambda: True, said.append).strategy == train.MCMCStrategy()

    def unread():
        raise AssertionError("the point count was read")

    for config in (train.FitConfig(data="d", out="o"), dataclasses.replace(f),
                   train.FitConfig(data="d", out="o", recipe=fast, steps=9,
                                   strategy=train.MCMCStrategy())):
        assert recipes.for_start(config, unread) is config


def test_fit_applies_the_wide_start_values_before_it_claims_the_run_folder(tmp_path,
                                                                          monkeypatch):
    """`fit` on a capture whose start is wide (a transforms.json without SfM points, not
    NeRF-synthetic) checks and trains the wide start's configuration; `wide_start` reads the
    model files alone (no image): false with SfM points (COLMAP) and for a NeRF-synthetic
    folder, whether given as a path or a loaded dataset."""
    from lgs_jax.io.datasets import load_dataset
    from lgs_jax.train import loop
    from lgs_jax.train.init import wide_start
    from tests.io.captures import tiny_colmap, tiny_transforms

    synthetic = tiny_capture(tmp_path / "s", views=2, size=8)  # transforms_train.json
    assert not wide_start(synthetic) and not wide_start(load_dataset(synthetic))
    tiny_colmap(str(tmp_path / "c"))
    os.remove(tmp_path / "c" / "images" / "a.png")
    assert not wide_start(str(tmp_path / "c"))
    data = os.path.dirname(tiny_transforms(str(tmp_path / "d")))
    assert wide_start(data) and wide_start(load_dataset(data))
    seen = []

    def claimed(config, path):
        seen.append(config)
        raise _Stop

    monkeypatch.setattr(loop.processes, "claimed", claimed)
    with pytest.raises(_Stop):
        train.fit(train.FitConfig(data=data, out=str(tmp_path / "o"),
                                  recipe=train.Recipe(name="fast")), log=lambda m: None)
    assert (seen[0].steps, seen[0].strategy) == (4000, train.DefaultStrategy())


@pytest.fixture
def fit_calls(monkeypatch):
    seen = []
    monkeypatch.setattr(train, "fit", lambda config, *a, **k: seen.append(config) or {})
    return seen


def test_fit_cli_takes_the_recipe_and_its_ablations(tmp_path, fit_calls, capsys):
    base = ["fit", "--data", str(tmp_path), "--out", str(tmp_path / "o")]
    fast = train.Recipe(name="fast")
    assert cli.main(base + ["--recipe", "fast", "--max-gaussians", "5000"]) == 0
    assert fit_calls[-1] == train.FitConfig(data=str(tmp_path), out=str(tmp_path / "o"),
                                            recipe=fast, max_gaussians=5000)
    ablations = (["--levels", "1"], ["--batch", "1"], ["--strategy", "mcmc"],
                 ["--no-early-stop"], ["--unseen-after", "0", "--growth", "mcmc"])
    for words in ablations:
        assert cli.main(base + ["--recipe", "fast", *words]) == 0
        config = fit_calls[-1]
        assert config.steps == 2000 and config.recipe.name == "fast"
        assert fit_cmd.config_of(cli.parser().parse_args(["fit"] + fit_cmd.argv(config))) \
            == config, words
    assert fit_calls[1].recipe.levels == 1 and fit_calls[2].recipe.batch == 1
    assert fit_calls[3].strategy == train.MCMCStrategy(cap_max=1_000_000)
    assert fit_calls[4].recipe.early_stop is False and fit_calls[4].recipe.levels == 3
    assert fit_calls[5].strategy == train.BudgetStrategy(unseen_after=0, growth="mcmc")
    assert cli.main(base + ["--unseen-after", "0"]) == 2  # the default recipe's strategy
    assert "the default strategy has no unseen_after" in capsys.readouterr().err
    with pytest.raises(SystemExit) as done:
        cli.main(["fit", "--help"])
    assert done.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for words in ("--recipe {default,fast}", "default 30000, fast 2000", "fast budget",
                  "default 1, fast 3", "docs/training.md", "5% per refinement"):
        assert words in text, words


# --- a whole fit -------------------------------------------------------------------------------

STRATEGY = train.BudgetStrategy(refine_start_iter=2, refine_every=4, refine_stop_iter=18,
                                budget=3, budget_until=12, unseen_after=6)


def _fast(data, out, **kwargs) -> train.FitConfig:
    """The fast recipe at a tiny size: 2 levels (1/2 size to step 12), 2 views a step, the
    budget strategy, an early stop over windows of 4 steps; SH degree 0 and no held-out views
    (`train_on_all`: the early stop needs none), which keep the compiles few and small."""
    recipe = train.Recipe(name="fast", levels=2, stop_window=4, stop_gain=0.5, sh_degree=0)
    return train.FitConfig(data=data, out=str(out), steps=24, recipe=recipe, strategy=STRATEGY,
                           backend="reference", init_points=64, train_on_all=True,
                           checkpoint_every=5, **kwargs)


class _Stop(Exception):
    pass


def test_a_tiny_fast_fit_is_deterministic_and_resumes_to_the_same_bits(tmp_path):
    """Run twice (a, then c): the same bits; each level starts with its own pair capacity
    (which changes no bit); c dies after step 7 (its checkpoint: step 5, at the coarse level)
    and is resumed: a's bits and a's result (its steps 1 to 5 ran again from the start, the
    rest resumed: a third, uninterrupted run would check nothing more); resumed again after
    its early stop, it stops at once. The early stop ends each at step 20, where the rule over
    metrics.jsonl's training losses says so."""
    data = tiny_capture(tmp_path / "d", views=5, size=16)
    lines = []
    result = train.fit(_fast(data, tmp_path / "a"), log=lines.append)
    assert "coarse to fine: 1/2 (8x8) from step 0, full resolution (16x16) from step 12" \
        in lines
    assert result["stopped_early_at"] == result["steps"] == 20
    entered = [m.split(", pair capacity")[0] for m in lines if ", pair capacity" in m]
    assert entered == ["step 1: images at 8x8 (1/2)", "step 13: images at 16x16 (full size)"]
    timing = {k for k in result if k.endswith("seconds")  # and the process's memory now
              or k.startswith(("compile_", "programs_"))} | {"ms_per_step", "memory"}

    def die(step, *_):
        if step == 7:
            raise _Stop

    with pytest.raises(_Stop):
        train.fit(_fast(data, tmp_path / "c"), watch=die, watch_every=0, log=lambda m: None)
    assert json.load(open(tmp_path / "c" / "checkpoint.json"))["step"] == 5
    second = train.fit(_fast(data, tmp_path / "c", resume=True), log=lambda m: None)
    assert {k: v for k, v in second.items() if k not in timing} == {
        k: v for k, v in result.items() if k not in timing}
    again = train.fit(_fast(data, tmp_path / "c", resume=True), log=lambda m: None)
    assert again["stopped_early_at"] == 20
    a, c = (np.load(tmp_path / run / "checkpoint.npz") for run in "ac")
    assert sorted(c.files) == sorted(a.files)
    for name in a.files:
        np.testing.assert_array_equal(a[name], c[name], err_msg=name)
    ply = [(tmp_path / run / "scene.ply").read_bytes() for run in "ac"]
    assert ply[0] == ply[1]
    rows = report.read_metrics(str(tmp_path / "a" / "metrics.jsonl"))
    losses = {r["step"]: r["loss"] for r in rows if "loss" in r}
    assert sorted(losses) == list(range(1, 21))
    assert early_stop.plateaued(losses, 20, 4, 0.5)
    refines = [r for r in rows if "refine_step" in r]
    assert [r["refine_step"] for r in refines] == [4, 8, 12, 16]
    assert result["gaussians"] == result["pool_size"] == STRATEGY.max_count(64, 24, 10**6)


def test_a_coarse_level_compiles_the_next_levels_step_ahead_and_no_grown_capacity(
        tmp_path, monkeypatch):
    """With compiling ahead, the coarse level (steps 0 to 11) asks its stepper for the next
    level's step (once) and for no grown capacity; the last level asks for the capacity after
    its own at every step (here recorded, not compiled)."""
    asked = []
    monkeypatch.setattr(ahead.Stepper, "ahead",
                        lambda self, args, size: asked.append(("level", int(args[8]))))
    monkeypatch.setattr(ahead.Stepper, "prepare",
                        lambda self, args, size, sig: asked.append(("grown", int(args[8]))))
    data = tiny_capture(tmp_path / "d", views=5, size=16)
    train.fit(_fast(data, tmp_path / "a", compile_ahead="thread"), log=lambda m: None)
    assert asked == [("level", 12)] + [("grown", step) for step in range(12, 20)]


@pytest.mark.slow  # CI time: three more compiles; ahead.Stepper.ahead has its unit test
def test_the_next_level_compiled_ahead_is_taken_and_changes_no_bit(tmp_path):
    """With compiling ahead in a thread (the GPU's default) the full-resolution step is
    compiled from halfway through the coarse level and taken at step 13 (the log says; the
    programs go through `step.lowering`, not the jit's cache): the bits of a run without it."""
    data = tiny_capture(tmp_path / "d", views=5, size=16)
    train.fit(_fast(data, tmp_path / "a", compile_ahead="off"), log=lambda m: None)
    lines = []
    train.fit(_fast(data, tmp_path / "b", compile_ahead="thread"), log=lines.append)
    assert "step 13: images at 16x16 (full size), pair capacity 1024 (compiled ahead)" in lines
    a, b = (np.load(tmp_path / run / "checkpoint.npz") for run in "ab")
    for name in a.files:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_time_to_quality_pairs_the_seeds_and_checks_the_targets(tmp_path, capsys):
    """benchmarks/time_to_quality.py's files and summary on made-up rows: a rerun replaces its
    rows; ours − gsplat's PSNR paired by seed against one standard error; the wall-time limit
    per scene (lego_train 30 s); the dry run prints the commands and runs nothing."""
    from benchmarks import time_to_quality as ttq

    path = str(tmp_path / "results.csv")
    rows = [dict(scene=scene, trainer=trainer, seed=seed, psnr=p, ssim=0.9, wall_s=w)
            for scene, trainer, w, ps in (("skull", "gsplat", 300, (25, 26)),
                                          ("skull", "lgs_jax_fast", 50, (24.5, 25.7)),
                                          ("lego_train", "gsplat", 60, (30, 30.2)),
                                          ("lego_train", "lgs_jax_fast", 31, (31, 31.4)))
            for seed, p in enumerate(ps)]
    ttq.merge(path, rows, ttq.FIELDS, ("scene", "trainer", "seed"))
    ttq.merge(path, [dict(rows[2], psnr=24.0)], ttq.FIELDS, ("scene", "trainer", "seed"))
    got = ttq.read_csv(path)
    assert len(got) == 8 and [r["psnr"] for r in got if r["trainer"] == "lgs_jax_fast"
                              and r["scene"] == "skull"] == ["25.7", "24.0"]
    skull, lego = ttq.target_rows(got)
    assert (skull["diff"], skull["error"]) == pytest.approx((-0.65, 0.35))  # -1.0, -0.3
    assert not skull["quality"] and skull["time"]
    assert lego["quality"] and not lego["time"] and lego["limit"] == 30
    assert ttq.main(["--summary", "--out", str(tmp_path), "--figure",
                     str(tmp_path / "f.png")]) == 0
    text = capsys.readouterr().out
    assert "| skull | lgs_jax_fast | 2 | 24.85 ± 0.85 |" in text
    assert "| lego_train | 2 | +1.10 ± 0.10 | met | 31.0 | 30 | missed |" in text
    assert (tmp_path / "f.png").stat().st_size > 0
    assert ttq.main(["--dry-run", "--scenes", "fox", "--seeds", "1", "--out",
                     str(tmp_path / "dry")]) == 0
    text = capsys.readouterr().out
    assert "lgs_jax fit --data" in text and "--recipe fast --seed 0" in text
    assert not (tmp_path / "dry" / "results.csv").exists()


def test_the_steps_key_leaves_out_what_only_the_loop_reads():
    """`Setup.for_step`: runs differing only in the image levels' schedule or the early stop
    share the training step's programs (`--no-early-stop` compiled the recipe's steps again);
    a field the step reads still tells them apart, and the step's own fields are kept."""
    from lgs_jax.train.config import LOOP_ONLY, Recipe, Setup

    fast = Setup(recipe=Recipe(name="fast"), steps=2000)
    loop_only = Setup(recipe=Recipe(name="fast", early_stop=False, stop_window=100, levels=2,
                                    full_resolution_at=0.7), steps=2000)
    assert fast != loop_only and fast.for_step == loop_only.for_step
    assert hash(fast.for_step) == hash(loop_only.for_step)
    assert Setup(recipe=Recipe(name="fast", batch=1), steps=2000).for_step != fast.for_step
    kept = {f: getattr(fast.recipe, f) for f in fast.recipe.__dataclass_fields__
            if f not in LOOP_ONLY}
    assert {f: getattr(fast.for_step.recipe, f) for f in kept} == kept
    assert fast.for_step.recipe.batch == 2 and fast.for_step.strategy == fast.strategy
