"""A dataset made ready for `fit`: the split, device arrays, the scene scale, the view order."""

from __future__ import annotations

import dataclasses
import os
from concurrent.futures import Future, ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

from ..io.dataset import Dataset, as_float, load_dataset
from ..scene import stack_cameras


@dataclasses.dataclass(frozen=True, eq=False)
class RunData:
    """train_cams: stacked training cameras; train_images (T, H, W, 3) on the host, float32 or
    uint8 as the dataset holds them (`TrainViews` puts them on the device, whole or a step's
    views at a time), train_names (file stems); test_cams, test_images (float32 numpy),
    test_names of the held-out views; background (3,);
    scene_scale: 1.1 x the largest camera distance from the cameras' mean centre (gsplat);
    points, colors: SfM points (may be empty); nerf_synthetic: white background."""

    train_cams: object
    train_images: np.ndarray
    train_names: list
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


def _stem(name: str) -> str:
    return os.path.splitext(os.path.basename(name))[0]


def prepare(data, downscale: int = 1, crop=None, train_on_all: bool = False) -> RunData:
    """`data` (a folder `load_dataset` reads, or a `Dataset`) ready for training; `crop` =
    (x0, y0, w, h) trains and evaluates on a window of every image (quick tests);
    `train_on_all` trains on every view, the split's held-out ones included, and holds out
    none."""
    d = data if isinstance(data, Dataset) else load_dataset(data, downscale=downscale)
    if train_on_all:
        d = dataclasses.replace(d, train=np.arange(len(d.names)), test=np.arange(0))
    elif len(d.train) == 0 or len(d.test) == 0:
        raise ValueError(f"data: {d.path} needs training views and held-out views; it has "
                         f"{len(d.test)} held-out of {len(d.names)} (train_on_all trains on "
                         f"every view and holds out none)")
    cams, images = _cropped(d, crop)
    return RunData(
        train_cams=stack_cameras([cams[i] for i in d.train]),
        train_images=np.asarray(images[d.train]), test_cams=[cams[i] for i in d.test],
        test_images=as_float(images[d.test]),
        train_names=[_stem(d.names[i]) for i in d.train],
        test_names=[_stem(d.names[i]) for i in d.test],
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


HOST_STREAM_BYTES = 2 << 30
"""`streams`' threshold where the device reports no memory limit (CPUs): 2 GiB."""


def streams(nbytes: int, setting: bool | None, device=None) -> bool:
    """Whether `fit` streams training images of `nbytes` (`Settings.stream_images`): the
    setting where it is a bool; None: when they would take more than an eighth of the device's
    memory (`memory_stats()["bytes_limit"]`), or more than `HOST_STREAM_BYTES` where the device
    reports no limit."""
    if setting is not None:
        return bool(setting)
    stats = (device or jax.devices()[0]).memory_stats() or {}
    limit = stats.get("bytes_limit")
    return nbytes > (limit // 8 if limit else HOST_STREAM_BYTES)


class TrainViews:
    """The training views of each step, as `step.train_step`'s (targets, idx) arguments: idx
    the step's views (`views_for_step`), targets their images (B, H, W, 3) float32 on the
    device (uint8 images converted there, `_float`), taken from the whole capture kept on the
    device, or streamed: each view copied from the host by a worker thread, the next step's
    copies started while a step runs (`prefetch`), so that device memory holds two batches
    instead of the capture and the host's copying (a staging copy of each image) runs beside
    the loop's dispatch instead of before it. The same values, and the same compiled step,
    either way: the same results to the bit. `close` ends the worker."""

    def __init__(self, images: np.ndarray, batch: int, seed: int, stream: bool):
        self.images, self.batch, self.seed, self.stream = images, batch, seed, stream
        self._whole = None if stream else jnp.asarray(images)
        self._worker = ThreadPoolExecutor(1, "lgs_jax-views") if stream else None
        self._copies: dict[int, Future] = {}

    def args(self, step: int):
        """(targets, idx) of 0-based `step`."""
        self.prefetch(step)
        return self._copies[step].result()

    def prefetch(self, step: int) -> None:
        """Start putting `step`'s views on the device (the latest two steps' kept)."""
        if step in self._copies:
            return
        self._copies = {k: v for k, v in self._copies.items() if k == step - 1}
        views = views_for_step(step, self.batch, self.images.shape[0], self.seed)
        if self.stream:
            self._copies[step] = self._worker.submit(self._copy, views)
        else:
            done, idx = Future(), jnp.asarray(views)
            done.set_result((_take(self._whole, idx), idx))
            self._copies[step] = done

    def _copy(self, views):
        """(targets, idx) of `views` from the host: each view's image as it lies in the capture
        (a view of the array, no gather on the host), stacked on the device."""
        return _stack(*(jax.device_put(self.images[v]) for v in views)), jnp.asarray(views)

    def close(self) -> None:
        """End the streaming worker (the copies it made stay valid)."""
        if self._worker is not None:
            self._worker.shutdown()


LEVELS = np.arange(256, dtype=np.float32) / np.float32(255)
"""x / 255 in float32 for every 8-bit value x, divided on the host (numpy's IEEE division, as
`io.dataset.as_float` and the image reader divide): XLA rewrites a division by a constant
into a multiplication by its reciprocal, which rounds some values differently."""


def _float(images):
    """`io.dataset.as_float` on the device (a lookup of `LEVELS`: the same bits)."""
    if images.dtype == jnp.uint8:
        return jnp.asarray(LEVELS)[images]
    return images


_take = jax.jit(lambda images, idx: _float(images[idx]))
_stack = jax.jit(lambda *views: _float(jnp.stack(views)))
