"""lgs_jax.train.heldout's compiles ahead: the evaluation's programs compiled in a thread before
the first evaluation (`Evaluations.ahead`) are the ones it runs, with the scores of the
programs `jax.jit` compiles at the evaluation, and `Evaluations.images` renders what
`step.render_views` does; a growth of the pair buffer counted ahead (`Evaluations.prepare`)
runs the program compiled ahead for it; after a score the next growth's render is compiled
ahead, after the final images nothing."""

import numpy as np

import lgs_jax
from lgs_jax.train import ahead as ahead_module, heldout
from lgs_jax.train.config import Setup
from lgs_jax.train.pool import from_gaussians
from lgs_jax.train.step import render_views
from tests import scenes

CAPACITY = 4099  # a capacity no other test renders at: the jit caches hold none at it yet


def _views():
    """Two held-out views of one scene (cameras, targets, background), the setup, and the pool
    of another scene to evaluate."""
    g = scenes.cast(scenes.scene(4), np.float32)
    cams = [scenes.camera(yaw=y) for y in (0.0, 0.3)]
    background = np.asarray(scenes.BACKGROUND, np.float32)
    targets = [np.asarray(lgs_jax.render(g, c, background=background).image) for c in cams]
    setup = Setup(backend="tiles")
    pool = from_gaussians(scenes.cast(scenes.scene(5), np.float32), 64)
    return cams, targets, background, setup, pool


def test_evaluations_run_the_programs_compiled_ahead_with_the_same_scores():
    cams, targets, background, setup, pool = _views()
    ahead = heldout.Evaluations(cams, targets, background, setup, CAPACITY, 2.0, "thread")
    ahead.ahead(pool)
    cached = heldout.compiled_programs()
    got = ahead.score(pool)
    assert heldout.compiled_programs() == cached  # the executables compiled ahead ran
    plain = heldout.Evaluations(cams, targets, background, setup, CAPACITY, 2.0)
    assert plain.score(pool) == got  # jit's compile of the same program: the same bits
    assert heldout.compiled_programs() != cached
    assert ahead.capacity == plain.capacity == CAPACITY  # the views need fewer pairs
    images = ahead.images(pool)
    want, _ = render_views(pool, cams, background, "tiles", CAPACITY, setup.recipe.raster)
    for image, w in zip(images, want):
        np.testing.assert_allclose(image, w, rtol=0, atol=1e-6)
    ahead.close()


def test_a_growth_prepared_ahead_runs_the_program_compiled_for_it():
    cams, targets, background, setup, pool = _views()
    ahead = heldout.Evaluations(cams, targets, background, setup, 1, 2.5, "thread")
    ahead.prepare(pool)  # the views need more than one pair: compiled for their growth
    cached = heldout.compiled_programs()
    got = ahead.score(pool)
    assert heldout.compiled_programs()[1] == cached[1]  # the render compiled ahead ran
    plain = heldout.Evaluations(cams, targets, background, setup, 1, 2.5)
    assert plain.score(pool) == got and ahead.capacity == plain.capacity > 1
    ahead.close()


def test_the_final_images_compile_nothing_ahead(monkeypatch):
    cams, targets, background, setup, pool = _views()
    prepared = []
    monkeypatch.setattr(ahead_module.Stepper, "prepare",
                        lambda self, args, size, sig: prepared.append(size))
    evaluations = heldout.Evaluations(cams, targets, background, setup, CAPACITY, 2.0, "thread")
    evaluations.images(pool)
    assert prepared == []
    evaluations.score(pool)
    assert prepared == [(CAPACITY, None)]
    evaluations.close()
