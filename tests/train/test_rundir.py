"""lgs_jax.train.rundir: a run folder is checked before any work and held by one `fit` at a time;
a resumed run must continue the saved one (its data, at least its steps)."""

import os

import pytest

from lgs_jax import cli, train
from lgs_jax.train import rundir

from .captures import run_folder, tiny_capture


@pytest.fixture
def saved(tmp_path):
    """A run folder of a tiny capture holding a checkpoint at step 60."""
    config = train.FitConfig(data=tiny_capture(tmp_path / "a"), out=str(tmp_path / "run"),
                             steps=60, init_points=50)
    run_folder(config, 60)
    return config


def _listing(folder):
    return {n: os.path.getmtime(os.path.join(folder, n)) for n in sorted(os.listdir(folder))}


def _fit(config, *flags):
    return cli.main(["fit", "--data", config.data, "--out", config.out, "--init-points", "50",
                     *flags])


def test_a_second_fit_on_a_folder_in_use_is_refused(saved, capsys):
    before = _listing(saved.out)
    with rundir.Lock(saved.out):  # another fit holds it
        assert _fit(saved, "--resume", "--steps", "61") == 2
        with pytest.raises(train.RunDirError, match="in use by another fit"):
            train.fit(train.FitConfig(data=saved.data, out=saved.out, resume=True, steps=61))
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--out: {saved.out} is in use by another fit (process " \
        f"{os.getpid()})" in err, err
    assert _listing(saved.out) == before  # the lock file is gone with its holder


def test_a_lock_is_released_and_its_file_removed(tmp_path):
    with rundir.Lock(str(tmp_path)):
        assert os.listdir(tmp_path) == [rundir.LOCK]
        assert rundir.run_dir_problem(str(tmp_path)) is None  # the lock alone: still empty
    assert os.listdir(tmp_path) == []
    with rundir.Lock(str(tmp_path)):  # free again
        pass


def test_resume_with_other_data_is_refused(saved, tmp_path, capsys):
    other = tiny_capture(tmp_path / "b", seed=1)
    before = _listing(saved.out)
    assert cli.main(["fit", "--data", other, "--out", saved.out, "--resume", "--steps",
                     "60"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--data: {saved.out} trained on " \
        f"{os.path.realpath(saved.data)} at downscale 1, not on {os.path.realpath(other)}" in err
    assert _fit(saved, "--resume", "--steps", "60", "--downscale", "2") == 2
    assert "not on " in capsys.readouterr().err
    assert _listing(saved.out) == before


def test_resume_with_fewer_steps_than_done_is_refused(saved, capsys):
    before = _listing(saved.out)
    assert _fit(saved, "--resume", "--steps", "10") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--steps: 10 is fewer than the 60 steps" in err, err
    assert _listing(saved.out) == before


def test_resume_with_another_recipe_is_refused_before_any_work(saved, capsys, monkeypatch):
    monkeypatch.setattr("lgs_jax.train.loop.prepare", lambda *a, **k: pytest.fail("work"))
    assert _fit(saved, "--resume", "--steps", "60", "--sh-degree", "1") == 2
    assert "--resume: the checkpoint was made with other settings (settings.sh_degree: 3 -> 1)" \
        in capsys.readouterr().err
