"""lgs_jax.train: SSIM against scikit-image, the loss falls on a tiny crop (CPU), checkpoints
resume, the `fit` CLI writes its outputs and never mixes two runs, the progress bar."""

import io
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from skimage.metrics import structural_similarity

import lgs_jax
from lgs_jax import cli
from lgs_jax import train


def test_ssim_equals_scikit_image():
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 1, (40, 48, 3))
    b = np.clip(a + rng.normal(0, 0.1, a.shape), 0, 1)
    want = structural_similarity(a, b, channel_axis=-1, data_range=1.0, gaussian_weights=True,
                                 sigma=1.5, use_sample_covariance=False)
    assert abs(float(train.ssim(jnp.asarray(a), jnp.asarray(b))) - want) < 1e-10
    assert abs(float(train.ssim(jnp.asarray(a), jnp.asarray(a))) - 1.0) < 1e-12


def test_sh_schedule_adds_one_band_every_period():
    masks = [np.asarray(train.sh_mask(step, 16, 1000)) for step in (0, 999, 1000, 2500, 9000)]
    assert [int(m.sum()) for m in masks] == [1, 1, 4, 9, 16]


def _data_dir(data_dir):
    path = os.path.join(data_dir, "lego_train")
    if not os.path.isdir(path):
        pytest.skip("lego_train not found")
    return path


def test_loss_falls_on_a_tiny_crop(data_dir):
    """40 Adam steps (3DGS rates) on one 32x32 crop of one training view: the loss falls by
    more than 5%, every step finite."""
    cams, images, _ = train.load_nerf(_data_dir(data_dir))
    cam = cams[1].cropped(84, 84, 32, 32)
    target = jnp.asarray(images[1, 84:116, 84:116])
    g = jax.tree.map(jnp.asarray, train.random_init(512, np.zeros(3), 0.6, sh_bases=1))
    params = train._split(g)
    opt = train.optimizer(40, 4.0)
    state = opt.init(params)
    bg = jnp.ones(3, jnp.float32)

    @jax.jit
    def step(params, state):
        loss, grads = jax.value_and_grad(lambda p: train.loss_fn(
            lgs_jax.render(train._join(p), cam, background=bg, capacity=8192).image,
            target))(params)
        updates, state = opt.update(grads, state, params)
        return train.optax.apply_updates(params, updates), state, loss

    losses = []
    for _ in range(40):
        params, state, loss = step(params, state)
        losses.append(float(loss))
    assert np.all(np.isfinite(losses))
    assert losses[-1] < 0.95 * losses[0], losses


def test_fit_writes_outputs_refuses_mixing_resumes_and_overwrites(data_dir, tmp_path, capsys):
    out = str(tmp_path / "run")
    args = ["fit", "--data", _data_dir(data_dir), "--steps", "4", "--out", out, "--gaussians",
            "256", "--eval-every", "2", "--crop", "80", "80", "32", "32", "--backend", "tiles"]
    assert cli.main(args) == 0
    for name in ("scene.ply", "optimizer.npz", "checkpoint.json", "metrics.jsonl",
                 "result.json", "heldout_r_0.png"):
        assert os.path.getsize(os.path.join(out, name)) > 0, name
    assert json.load(open(os.path.join(out, "checkpoint.json")))["step"] == 4
    args[args.index("--steps") + 1] = "6"
    assert cli.main(args) == 2  # an existing run is never silently mixed with a new one
    assert "--resume" in capsys.readouterr().err
    assert cli.main(args + ["--resume"]) == 0
    steps = [json.loads(line).get("step") for line in open(os.path.join(out, "metrics.jsonl"))]
    assert steps.count(5) >= 1 and steps.count(1) == 1  # resumed at 4, did not restart
    assert lgs_jax.load_ply(os.path.join(out, "scene.ply")).num == 256
    args[args.index("--steps") + 1] = "0"
    assert cli.main(args + ["--overwrite"]) == 0  # clears the old run: nothing of it is left
    result = json.load(open(os.path.join(out, "result.json")))
    assert result["steps"] == 0 and result["ms_per_step"] is None
    rows = [json.loads(line) for line in open(os.path.join(out, "metrics.jsonl"))]
    assert [r["step"] for r in rows] == [0] and "heldout_psnr" in rows[0]
    assert not os.path.exists(os.path.join(out, "checkpoint.json"))


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
        train.fit("unused", 1, str(tmp_path))


@pytest.mark.parametrize("kwargs,match", [(dict(steps=-1), "steps: expected an int >= 0"),
                                          (dict(n_gaussians=0), "n_gaussians")])
def test_fit_refuses_bad_counts(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        train.fit("unused", **{"steps": 1, "out": str(tmp_path), **kwargs})


def test_fit_usage_errors_exit_2(tmp_path, capsys):
    assert cli.main(["fit", "--data", str(tmp_path / "none"), "--steps", "1", "--out",
                     str(tmp_path / "o")]) == 2
    assert "--data" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        cli.main(["fit", "--data", str(tmp_path), "--steps", "1", "--out", str(tmp_path),
                  "--resume", "--overwrite"])
    assert exit_.value.code == 2


def test_progress_bar_redraws_while_a_step_runs():
    """Step, loss, rate and ETA; redrawn by the timer without any step finishing."""
    stream = io.StringIO()
    bar = train._Progress(0, 10, file=stream, interval=0.05)
    time.sleep(0.5)
    assert stream.getvalue().count("compiling the first step") >= 4
    bar.step(0.25)
    bar.step(0.125)
    bar.close()
    last = stream.getvalue().split("\r")[-1]
    assert "2/10" in last and "loss=0.1250" in last and "<" in last and "step/s" in last


def test_fit_needs_held_out_views(tmp_path):
    import matplotlib.image

    data = tmp_path / "data"
    (data / "train").mkdir(parents=True)
    frames = []
    for i in (1, 2):
        matplotlib.image.imsave(data / "train" / f"r_{i}.png", np.zeros((8, 8, 4)))
        frames.append(dict(file_path=f"./train/r_{i}", transform_matrix=np.eye(4).tolist()))
    (data / "transforms_train.json").write_text(json.dumps(dict(camera_angle_x=0.7,
                                                                frames=frames)))
    with pytest.raises(ValueError, match="needs training views and held-out views"):
        train.fit(str(data), 1, str(tmp_path / "out"))
