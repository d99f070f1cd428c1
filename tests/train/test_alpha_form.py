"""`Recipe.alpha_form` (the exponent's evaluation form of training renders, the paper's Table V):
its RasterConfig switches, the backends that compute it, a tiny fit per form on the CPU's
default backend (different bits, close results), and a resume that changes it refused."""

import json

import numpy as np
import pytest

import lgs_jax
from lgs_jax import cli, train
from lgs_jax.render import default_backend
from lgs_jax.train import checkpoint

from .captures import run_folder, tiny_capture

FORMS = ("local", "global", "difference")


def test_each_form_sets_its_raster_switches_and_keeps_the_others():
    R = train.Recipe
    assert R().alpha_form == "local" and R().raster == lgs_jax.RasterConfig()
    assert R(alpha_form="global").raster == lgs_jax.RasterConfig(local_coords=False)
    assert R(alpha_form="difference").raster == lgs_jax.RasterConfig(hoist=False)
    both = R(alpha_form="global", convention="gsplat", antialiased=True).raster
    assert both == lgs_jax.RasterConfig("gsplat", antialiased=True, local_coords=False)
    with pytest.raises(ValueError, match="alpha_form: expected one of"):
        R(alpha_form="hoisted")


@pytest.mark.parametrize("backend", ["reference", "pallas_vanilla"])
def test_global_form_is_refused_where_the_backend_computes_the_difference_form(backend):
    with pytest.raises(ValueError, match=f"recipe.alpha_form: 'global' needs a backend of "
                                         f".*'{backend}' computes the difference form"):
        train.Setup(recipe=train.Recipe(alpha_form="global"), backend=backend)
    for form in ("local", "difference"):  # the default as before; difference is theirs
        train.Setup(recipe=train.Recipe(alpha_form=form), backend=backend)
    for ok in ("tiles", "pallas"):
        train.Setup(recipe=train.Recipe(alpha_form="global"), backend=ok)


def test_a_checkpoint_records_the_form_and_an_older_one_counts_as_local():
    config = train.FitConfig(data="d", out="o")
    saved = checkpoint.config_of(config)
    assert saved["settings"]["alpha_form"] == "local"
    other = checkpoint.config_of(train.FitConfig(data="d", out="o",
                                                 recipe=train.Recipe(alpha_form="global")))
    assert "settings.alpha_form: 'local' -> 'global'" in checkpoint.config_mismatch(saved, other)
    older = json.loads(json.dumps(saved))
    del older["settings"]["alpha_form"]
    defaults = checkpoint.default_config(config)
    assert checkpoint.config_mismatch(older, saved, defaults) is None
    assert "alpha_form" in checkpoint.config_mismatch(older, other, defaults)


def test_resume_with_another_form_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    config = train.FitConfig(data=tiny_capture(tmp_path / "a"), out=str(tmp_path / "run"),
                             steps=6, init_points=50)
    run_folder(config, 6)
    monkeypatch.setattr("lgs_jax.train.loop.prepare", lambda *a, **k: pytest.fail("work"))
    assert cli.main(["fit", "--data", config.data, "--out", config.out, "--init-points", "50",
                     "--resume", "--steps", "6", "--alpha-form", "difference"]) == 2
    assert "settings.alpha_form: 'local' -> 'difference'" in capsys.readouterr().err


@pytest.mark.slow  # three training steps compiled on `tiles`: minutes on a CI core
def test_a_tiny_fit_per_form_runs_and_the_forms_differ_by_rounding(tmp_path):
    """The same seed and data (32x32 photos: four tiles, so that tile-local and global
    coordinates differ) trained 6 steps in each form on the CPU's default backend (`tiles`, which
    honours the form): each form's bits differ (the form reached the training renders), the
    scenes and their held-out renders stay close (the forms differ by float32 rounding)."""
    data = tiny_capture(tmp_path / "capture", views=4, size=32)
    scenes, images, results = {}, {}, {}
    for form in FORMS:
        out = tmp_path / form
        config = train.FitConfig(data=data, out=str(out), steps=6, init_points=200,
                                 pool_size=256, eval_every=100, checkpoint_every=100,
                                 recipe=train.Recipe(alpha_form=form))
        results[form] = train.fit(config, log=lambda m: None)
        scenes[form] = lgs_jax.load_ply(str(out / "scene.ply"))
        held = train.evaluate(scenes[form], data, config=config.recipe.raster)
        assert held["psnr"] == pytest.approx(results[form]["heldout_psnr"], abs=1e-4)
        ds = lgs_jax.load_dataset(data)
        cam = ds.cameras[ds.test[0]]
        images[form] = np.asarray(lgs_jax.render(
            scenes[form], cam, background=ds.background, config=config.recipe.raster).image)
    assert {r["backend"] for r in results.values()} == {default_backend()}
    assert {r["gaussians"] for r in results.values()} == {results["local"]["gaussians"]}
    for form in ("global", "difference"):
        a, b = scenes["local"], scenes[form]
        assert not np.array_equal(a.means, b.means), form
        np.testing.assert_allclose(a.means, b.means, atol=1e-4, err_msg=form)
        np.testing.assert_allclose(a.sh, b.sh, atol=1e-3, err_msg=form)
        assert not np.array_equal(images["local"], images[form]), form
        np.testing.assert_allclose(images["local"], images[form], atol=1e-3, err_msg=form)
        assert results[form]["heldout_psnr"] == pytest.approx(results["local"]["heldout_psnr"],
                                                              abs=0.01)
