"""`fit` on captures whose images differ in size: a step's views share one size (the view order
per epoch), each view is rendered at its own size against its own image, and a whole run
(streamed or not, two sizes, two views a step, bilateral grids) trains to the same bits and
writes each camera at its size; each size keeps its own compile ahead."""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lgs_jax
from lgs_jax import train
from lgs_jax.io.datasets import Dataset
from lgs_jax.train import ahead, feed as train_data, losses, optim, pool as train_pool
from lgs_jax.train.config import Setup
from lgs_jax.train.step import train_step

SIZES = ((32, 24), (24, 32))  # landscape and portrait, alternating over the views
BACKGROUND = np.zeros(3, np.float32)
_image = jax.jit(lambda g, cam: lgs_jax.render(g, cam, background=BACKGROUND,
                                               backend="reference", capacity=4096).image)


def _look_at(eye) -> np.ndarray:
    """World-to-camera matrix (OpenCV axes) of a camera at `eye` looking at the origin, y down
    along -world z."""
    forward = -np.asarray(eye, np.float64) / np.linalg.norm(eye)
    right = np.cross(forward, [0.0, 0.0, -1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    view = np.eye(4)
    view[:3, :3] = np.stack([right, down, forward])
    view[:3, 3] = -view[:3, :3] @ eye
    return view.astype(np.float32)


def _scene(n: int = 48, seed: int = 0) -> lgs_jax.Gaussians:
    rng = np.random.default_rng(seed)
    f = lambda *a: rng.normal(*a).astype(np.float32)
    return lgs_jax.Gaussians(means=f(0, 0.4, (n, 3)), quats=f(0, 1, (n, 4)),
                             log_scales=np.full((n, 3), -2.0, np.float32) + f(0, 0.2, (n, 3)),
                             logit_opacities=f(0.5, 1.0, n), sh=f(0, 0.5, (n, 1, 3)))


@pytest.fixture(scope="module")
def capture() -> Dataset:
    """Nine views of a random scene on a circle, 32x24 and 24x32 in turn, rendered at their
    sizes (view 0 held out, as every 8th is)."""
    g, cams, images = _scene(), [], []
    for i in range(9):
        a = 2 * np.pi * i / 9
        w, h = SIZES[i % 2]
        cams.append(lgs_jax.Camera(viewmat=_look_at(3.0 * np.array([np.cos(a), np.sin(a), 0.3])),
                                   fx=np.float32(30), fy=np.float32(30), cx=np.float32(w / 2),
                                   cy=np.float32(h / 2), width=w, height=h))
        images.append(np.asarray(_image(g, cams[-1])))
    points = np.asarray(g.means)
    return Dataset(path="two_sizes", names=tuple(f"v{i}.png" for i in range(9)), images=images,
                   cameras=tuple(cams), points=points, colors=np.full_like(points, 0.5),
                   train=np.arange(1, 9), test=np.arange(1), background=BACKGROUND)


@pytest.mark.parametrize("batch", [2, 3])
def test_a_steps_views_share_a_size_and_each_epoch_sees_every_view(batch):
    groups = np.array([0, 1, 1, 0, 2, 1, 0, 0, 1, 2])
    per_epoch = int(np.sum(-(-np.bincount(groups) // batch)))
    steps = [train_data.views_for_step(s, batch, len(groups), 7, groups)
             for s in range(3 * per_epoch)]
    for views in steps:
        assert views.shape == (batch,) and len(set(groups[views])) == 1, views
    for e in range(3):
        seen = np.concatenate(steps[e * per_epoch:(e + 1) * per_epoch])
        assert set(seen) == set(range(len(groups)))
        assert len(seen) == per_epoch * batch  # a size's last batch filled from its own views
    again = train_data.views_for_step(per_epoch + 1, batch, len(groups), 7, groups)
    np.testing.assert_array_equal(again, steps[per_epoch + 1])  # (step, seed) alone
    epochs = [np.concatenate(steps[e * per_epoch:(e + 1) * per_epoch]) for e in range(2)]
    assert np.any(epochs[0] != epochs[1])  # a new order each epoch
    # one view a step: the one-size order, whatever the sizes
    for s in range(12):
        np.testing.assert_array_equal(train_data.views_for_step(s, 1, 10, 7, groups),
                                      train_data.views_for_step(s, 1, 10, 7))


def test_prepare_keeps_each_views_size(capture):
    rd = train_data.prepare(capture)
    assert rd.train_sizes == tuple(SIZES[i % 2] for i in range(1, 9))
    assert rd.sizes == [SIZES[1], SIZES[0]] and list(rd.groups()) == [0, 1] * 4
    assert isinstance(rd.train_images, list) and rd.test_images.shape == (1, 24, 32, 3)
    for i in range(8):
        cam = rd.train_camera(i)
        assert (cam.width, cam.height) == rd.train_sizes[i]
        assert rd.train_images[i].shape == (cam.height, cam.width, 3)
        np.testing.assert_array_equal(cam.viewmat, capture.cameras[i + 1].viewmat)
    assert train_data.nbytes(rd.train_images) == 8 * 32 * 24 * 3 * 4
    # the same capture with one size in its training views: an array, one group
    one = dataclasses.replace(capture, train=np.arange(1, 9, 2))
    rd = train_data.prepare(one)
    assert rd.train_images.shape == (4, 32, 24, 3) and rd.groups() is None
    with pytest.raises(ValueError, match=r"crop: .* of the 24x32, 32x24 images"):
        train_data.prepare(capture, crop=(0, 0, 30, 20))
    rd = train_data.prepare(capture, crop=(2, 3, 20, 16))
    assert rd.train_images.shape == (8, 16, 20, 3) and rd.groups() is None


def test_each_view_is_rendered_at_its_size_against_its_image(capture):
    """A step's loss on views of either size is the loss of `render` at the view's own camera
    against its own image (a view paired with another's camera or image, or rendered at the
    other size, would not be)."""
    rd = train_data.prepare(capture)
    setup = Setup(train.Recipe(sh_degree=0), train.Strategy(), 10, rd.scene_scale, "reference")
    pool = train_pool.from_gaussians(jax.tree.map(jnp.asarray, _scene(seed=1)), 64)
    opt_state = optim.optimizer(setup.recipe, 10, rd.scene_scale).init(pool.params)
    views = [5, 1]  # 24x32 (the first size is 24x32, view 2 is 32x24)
    targets = jnp.stack([jnp.asarray(rd.train_images[v]) for v in views])
    state = jax.tree.map(jnp.copy, (pool, opt_state, setup.strategy.init(pool, 1.0)))  # donated
    # go True, as `fit` passes it (an array): the program of the call below
    m = train_step(*state, None, rd.train_cams, targets, jnp.asarray(views),
                   jnp.asarray(BACKGROUND), 0, jax.random.key(0), None, jnp.asarray(True),
                   setup=setup, capacity=4096)[4]
    g = train_pool.render_gaussians(pool.params, pool.active)
    want = np.mean([float(losses.loss_fn(_image(g, rd.train_camera(v)),
                                         jnp.asarray(rd.train_images[v]))) for v in views])
    assert abs(float(m["loss"]) - want) < 1e-5 * want, (float(m["loss"]), want)
    # go False (`fit`: the step before overflowed): the state comes back unchanged
    state = (pool, opt_state, setup.strategy.init(pool, 1.0))
    before = jax.tree.map(np.asarray, state)
    kept = train_step(*jax.tree.map(jnp.copy, state), None, rd.train_cams, targets,
                      jnp.asarray(views), jnp.asarray(BACKGROUND), 0, jax.random.key(0), None,
                      jnp.asarray(False), setup=setup, capacity=4096)
    assert bool(kept[4]["fits"]) and bool(kept[4]["ok"])
    for a, b in zip(jax.tree.leaves(kept[:3]), jax.tree.leaves(before), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow  # CI time: test_each_view_is_rendered_at_its_size covers the sizes
def test_fit_trains_on_two_sizes_to_the_same_bits_streamed_or_not(capture, tmp_path):
    """With bilateral grids, which slice each view at its own size."""
    recipe = train.Recipe(batch=2, sh_degree=0, bilateral_grid=True)
    runs = {}
    for stream in (False, True):
        lines = []
        out = tmp_path / f"stream{stream}"
        config = train.FitConfig(data=capture.path, out=str(out), steps=4, recipe=recipe,
                                 backend="reference", eval_every=100, checkpoint_every=100,
                                 stream_images=stream)
        runs[stream] = train.fit(config, capture, log=lines.append)
        assert any("2 sizes (24x32, 32x24)" in m for m in lines), lines
    assert runs[True]["heldout_psnr"] == runs[False]["heldout_psnr"] > 10
    a, b = (np.load(tmp_path / f"stream{s}" / "checkpoint.npz") for s in (False, True))
    for key in a.files:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    grids = np.load(tmp_path / "streamFalse" / "bilateral_grids.npz")
    assert grids["grids"].shape == (8, 12, 8, 16, 16) and list(grids["names"])[0] == "v1"
    assert 0 < np.max(np.abs(grids["grids"][:, 0] - 1)) < 0.1  # moved from the identity
    cams = json.loads((tmp_path / "streamFalse" / "cameras.json").read_text())
    by_name = {c["img_name"]: (c["width"], c["height"]) for c in cams}
    assert by_name == {f"v{i}": SIZES[i % 2] for i in range(9)}


def test_each_size_keeps_its_own_compile_ahead():
    """`ahead.Stepper` with steps of two image sizes in turn: each size's compile ahead is
    kept and taken at its growth (one job replacing the other would compile without end)."""
    lowered = []

    class Lowered:
        def __init__(self, size, n):
            self.size, self.n = size, n

        def compile(self):
            lowered.append(self.n)
            return lambda *args: ("executable", self.n, self.size)

    class Jitted:
        def __call__(self, *args, size):
            return ("jit", size)

        def lower(self, x, size):
            return Lowered(size, x.shape[0])

    stepper = ahead.Stepper(Jitted(), lambda size: dict(size=size), ahead.Sizes(1.5))
    small, large = (jnp.zeros(3),), (jnp.zeros(4),)
    sigs = [ahead.signature(a) for a in (small, large)]
    for _ in range(3):  # the sizes in turn, each preparing the same following size
        for args, sig in zip((small, large), sigs):
            stepper.run(args, (1024, None), sig)
            stepper.prepare(args, (1024, None), sig)
    for args, sig, n in zip((small, large), sigs, (3, 4)):
        size, _, taken = stepper.grow((1024, None), (1100, 0), sig)
        assert taken and size == (2048, None)
        assert stepper.run(args, size, sig) == ("executable", n, (2048, None))
    assert sorted(lowered) == [3, 4]  # one compile each
    stepper.close()


def test_compiles_ahead_of_shapes_no_longer_run_are_dropped(monkeypatch):
    """Only the `KEPT_SIGNATURES` latest signatures keep their compile ahead (a pool that grew
    leaves its old shapes behind for good)."""
    monkeypatch.setattr(ahead, "KEPT_SIGNATURES", 2)
    class Jitted:
        def __call__(self, *args, size):
            return ("jit", size)

        def lower(self, *args, size):
            return type("L", (), {"compile": lambda self: print})()

    stepper = ahead.Stepper(Jitted(), lambda size: dict(size=size), ahead.Sizes(1.5))
    args = [(jnp.zeros(n),) for n in (3, 4, 5)]
    sigs = [ahead.signature(a) for a in args]
    for a, sig in zip(args[:2], sigs[:2]):
        stepper.run(a, (1024, None), sig)
        stepper.prepare(a, (1024, None), sig)
    stepper.run(args[2], (1024, None), sigs[2])  # the third shape: the first is dropped
    assert not stepper.grow((1024, None), (1100, 0), sigs[0])[2]
    assert stepper.grow((1024, None), (1100, 0), sigs[1])[2]
    stepper.close()
