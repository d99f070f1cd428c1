"""A dataset made ready for `fit`: the split, device arrays, the scene scale, the view order."""

from __future__ import annotations

import dataclasses
import os

import jax
import jax.numpy as jnp
import numpy as np

from ..io.dataset import Dataset, load_dataset
from ..scene import stack_cameras


@dataclasses.dataclass(frozen=True, eq=False)
class RunData:
    """train_cams: stacked training cameras; train_images (T, H, W, 3) on the device; test_cams,
    test_images (numpy), test_names (file stems) of the held-out views; background (3,);
    scene_scale: 1.1 x the largest camera distance from the cameras' mean centre (gsplat);
    points, colors: SfM points (may be empty); nerf_synthetic: white background."""

    train_cams: object
    train_images: jax.Array
    test_cams: list
    test_images: np.ndarray
    test_names: list
    background: np.ndarray
    scene_scale: float
    points: np.ndarray
    colors: np.ndarray
    nerf_synthetic: bool


def _cropped(d: Dataset, crop):
    """(cameras, images) of `d`, cropped to the window crop = (x0, y0, w, h) when given."""
    cams, images = list(d.cameras), d.images
    if isinstance(images, list):
        raise ValueError(f"data: {d.path} has images of several sizes; fit needs one size")
    if not crop:
        return cams, images
    x0, y0, w, h = crop
    if min(crop) < 0 or w < 1 or h < 1 or x0 + w > cams[0].width or y0 + h > cams[0].height:
        raise ValueError(f"crop: {tuple(crop)} is not a non-empty window (x0, y0, w, h) of "
                         f"the {cams[0].width}x{cams[0].height} images")
    return [c.cropped(x0, y0, w, h) for c in cams], images[:, y0:y0 + h, x0:x0 + w]


def prepare(data, downscale: int = 1, crop=None) -> RunData:
    """`data` (a folder `load_dataset` reads, or a `Dataset`) ready for training; `crop` =
    (x0, y0, w, h) trains and evaluates on a window of every image (quick tests)."""
    d = data if isinstance(data, Dataset) else load_dataset(data, downscale=downscale)
    if len(d.train) == 0 or len(d.test) == 0:
        raise ValueError(f"data: {d.path} needs training views and held-out views; it has "
                         f"{len(d.test)} held-out of {len(d.names)}")
    cams, images = _cropped(d, crop)
    return RunData(
        train_cams=stack_cameras([cams[i] for i in d.train]),
        train_images=jnp.asarray(images[d.train]), test_cams=[cams[i] for i in d.test],
        test_images=np.asarray(images[d.test]),
        test_names=[os.path.splitext(os.path.basename(d.names[i]))[0] for i in d.test],
        background=np.asarray(d.background, np.float32), scene_scale=1.1 * d.extent,
        points=np.asarray(d.points), colors=np.asarray(d.colors),
        nerf_synthetic=bool(np.all(d.background == 1)))


def views_for_step(step: int, batch: int, n_train: int, seed: int) -> np.ndarray:
    """Training view indices of 0-based `step`: a new random order of all training views every
    epoch (gsplat's shuffling DataLoader), read `batch` at a time. Depends only on (step, seed),
    so a resumed run sees the same views as an uninterrupted one."""
    pos = step * batch + np.arange(batch)
    out = np.empty(batch, np.int64)
    for epoch in np.unique(pos // n_train):
        order = np.random.default_rng([seed, int(epoch)]).permutation(n_train)
        here = pos // n_train == epoch
        out[here] = order[pos[here] % n_train]
    return out
