"""A dataset made ready for `fit`: the split, device arrays, the scene scale, the view order."""

from __future__ import annotations

import dataclasses
import functools
import os
from concurrent.futures import Future, ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

from ..io.datasets import Dataset, as_float, dataset_info, load_dataset
from ..scene import stack_cameras


@dataclasses.dataclass(frozen=True, eq=False)
class RunData:
    """train_cams: the training cameras stacked (`stack_any`: each view's own size is
    train_sizes[i], its image's); train_images on the host, float32 or uint8 as the dataset
    holds them (`TrainViews` puts them on the device, whole or a step's views at a time):
    (T, H, W, 3) where every view has one size, else a list of (H_i, W_i, 3); train_sizes
    ((width, height) per training view), train_names (file stems); test_cams, test_images
    (float32 numpy, a list where sizes differ), test_names of the held-out views;
    background (3,); scene_scale: 1.1 x the largest camera distance from the cameras' mean
    centre (gsplat); points, colors: SfM points (may be empty); nerf_synthetic: white
    background."""

    train_cams: object
    train_images: np.ndarray | list
    train_sizes: tuple
    train_names: list
    test_cams: list
    test_images: np.ndarray | list
    test_names: list
    background: np.ndarray
    scene_scale: float
    points: np.ndarray
    colors: np.ndarray
    nerf_synthetic: bool

    @property
    def sizes(self) -> list:
        """The distinct training image sizes (width, height), in order of first appearance."""
        return list(dict.fromkeys(self.train_sizes))

    def groups(self) -> np.ndarray | None:
        """Each training view's index in `sizes` (`views_for_step`), None for one size."""
        sizes = self.sizes
        if len(sizes) == 1:
            return None
        return np.array([sizes.index(s) for s in self.train_sizes])

    def train_camera(self, i: int, cams=None):
        """Training view i's camera at its own image size, from `cams` (a stack like
        train_cams, e.g. at optimized poses) or train_cams."""
        width, height = self.train_sizes[i]
        stack = self.train_cams if cams is None else cams
        return dataclasses.replace(jax.tree.map(lambda x: x[i], stack), width=width,
                                   height=height)


def stack_any(cams: list):
    """Cameras of any sizes stacked (`stack_cameras`), their static size set to the first's:
    the stack holds every view's parameters; a batch of one size is rendered at its size
    (`step.train_step` sets it from its images)."""
    first = cams[0]
    return stack_cameras([dataclasses.replace(c, width=first.width, height=first.height)
                          for c in cams])


def nbytes(images) -> int:
    """Bytes of `images`: an array, or a list of arrays of several sizes."""
    return images.nbytes if isinstance(images, np.ndarray) else sum(im.nbytes for im in images)


def _take_views(images, idx):
    """The views `idx` of `images` (an array, or a list of views of several sizes): an array
    where they share one size, else a list."""
    if isinstance(images, np.ndarray):
        return images[idx]
    views = [images[i] for i in idx]
    return np.stack(views) if len({v.shape for v in views}) == 1 else views


def _cropped(d: Dataset, crop):
    """(cameras, images) of `d`, cropped to the window crop = (x0, y0, w, h) when given."""
    cams, images = list(d.cameras), d.images
    if not crop:
        return cams, images
    x0, y0, w, h = crop
    width, height = min(c.width for c in cams), min(c.height for c in cams)
    if min(crop) < 0 or w < 1 or h < 1 or x0 + w > width or y0 + h > height:
        sizes = sorted({f"{c.width}x{c.height}" for c in cams})
        raise ValueError(f"crop: {tuple(crop)} is not a non-empty window (x0, y0, w, h) of "
                         f"the {', '.join(sizes)} images")
    if isinstance(images, list):
        images = np.stack([im[y0:y0 + h, x0:x0 + w] for im in images])
    else:
        images = images[:, y0:y0 + h, x0:x0 + w]
    return [c.cropped(x0, y0, w, h) for c in cams], images


def _stem(name: str) -> str:
    return os.path.splitext(os.path.basename(name))[0]


def prepare(data, downscale: int = 1, crop=None, train_on_all: bool = False,
            dtype=np.float32) -> RunData:
    """`data` (a folder `load_dataset` reads at `downscale` as `dtype` images, or a `Dataset`)
    ready for training; `crop` = (x0, y0, w, h) trains and evaluates on a window of every
    image (quick tests); `train_on_all` trains on every view, the split's held-out ones
    included, and holds out none."""
    d = data if isinstance(data, Dataset) else load_dataset(data, downscale=downscale,
                                                            dtype=dtype)
    if train_on_all:
        d = dataclasses.replace(d, train=np.arange(len(d.names)), test=np.arange(0))
    elif len(d.train) == 0 or len(d.test) == 0:
        raise ValueError(f"data: {d.path} needs training views and held-out views; it has "
                         f"{len(d.test)} held-out of {len(d.names)} (train_on_all trains on "
                         f"every view and holds out none)")
    cams, images = _cropped(d, crop)
    test = _take_views(images, d.test)
    return RunData(
        train_cams=stack_any([cams[i] for i in d.train]),
        train_images=_take_views(images, d.train),
        train_sizes=tuple((cams[i].width, cams[i].height) for i in d.train),
        test_cams=[cams[i] for i in d.test],
        test_images=as_float(test) if isinstance(test, np.ndarray) else list(map(as_float,
                                                                                 test)),
        train_names=[_stem(d.names[i]) for i in d.train],
        test_names=[_stem(d.names[i]) for i in d.test],
        background=np.asarray(d.background, np.float32), scene_scale=1.1 * d.extent,
        points=np.asarray(d.points), colors=np.asarray(d.colors),
        nerf_synthetic=dataset_info(d).nerf_synthetic)


def views_for_step(step: int, batch: int, n_train: int, seed: int,
                   groups: np.ndarray | None = None) -> np.ndarray:
    """Training view indices of 0-based `step`: a new random order of all training views every
    epoch (gsplat's shuffling DataLoader), read `batch` at a time. Depends only on (step, seed),
    so a resumed run sees the same views as an uninterrupted one.

    groups: each view's image size (an index; `RunData.groups`), or None for one size. A step's
    views must share a size, so with several sizes and `batch` > 1 an epoch is that order cut
    into batches of one size each (`_one_size_batches`)."""
    if groups is not None and batch > 1:
        return _one_size_batches(step, batch, groups, seed)
    pos = step * batch + np.arange(batch)
    out = np.empty(batch, np.int64)
    for epoch in np.unique(pos // n_train):
        here = pos // n_train == epoch
        out[here] = epoch_order(seed, int(epoch), n_train)[pos[here] % n_train]
    return out


@functools.lru_cache(maxsize=4)
def epoch_order(seed: int, epoch: int, n_train: int) -> np.ndarray:
    """The random order of the `n_train` training views in `epoch` (read-only; kept for the
    epoch's steps: one generator an epoch rather than one a step)."""
    order = np.random.default_rng([seed, epoch]).permutation(n_train)
    order.flags.writeable = False
    return order


def _one_size_batches(step: int, batch: int, groups: np.ndarray, seed: int) -> np.ndarray:
    """`views_for_step` with several sizes: each epoch's random order of the views, split by
    size (in that order), each size's views read `batch` at a time (its last batch filled up
    from its first views again), and the epoch's batches in a random order. Every view is
    seen once an epoch (a size whose count `batch` does not divide: some twice)."""
    counts = np.bincount(groups)
    per_epoch = int(np.sum(-(-counts // batch)))
    epoch, k = divmod(step, per_epoch)
    rng = np.random.default_rng([seed, epoch])
    order = rng.permutation(len(groups))
    batches = []
    for g in range(len(counts)):
        mine = order[groups[order] == g]
        batches += list(np.resize(mine, -(-len(mine) // batch) * batch).reshape(-1, batch))
    return batches[rng.permutation(per_epoch)[k]].astype(np.int64)


HOST_STREAM_BYTES = 2 << 30
"""`streams`' threshold where the device reports no memory limit (CPUs): 2 GiB."""


def streams(nbytes: int, setting: bool | None, device=None) -> bool:
    """Whether `fit` streams training images of `nbytes` (`FitConfig.stream_images`): the
    setting where it is a bool; None: on a device that reports a memory limit
    (`memory_stats()["bytes_limit"]`: a GPU, whose memory a run competes for), and elsewhere
    (a CPU, whose memory is the host's) when they take more than `HOST_STREAM_BYTES`. The
    device: `device`, or this process's first."""
    if setting is not None:
        return bool(setting)
    stats = (device or jax.local_devices()[0]).memory_stats() or {}
    return bool(stats.get("bytes_limit")) or nbytes > HOST_STREAM_BYTES


class TrainViews:
    """The training views of each step, as `step.train_step`'s (targets, idx) arguments: idx
    the step's views (`views_for_step`), targets their images (B, H, W, 3) on the device as
    the capture stores them (8-bit or float; the step converts them, `to_float`), taken from
    the whole capture kept on the device, or streamed: the views copied from the host by a
    worker thread, the next step's copies started while a step runs (`prefetch`), so that
    device memory holds two batches instead of the capture and the host's copying (a staging
    copy of each image) runs beside the loop's dispatch instead of before it; the worker
    dispatches no program (one view: its image as it lies in the capture, a view of the
    array; several: stacked on the host). The same values, and the same compiled step,
    either way: the same results to the bit. `close` ends the worker.

    `images` is (T, H, W, 3), or a list of views of several sizes (`RunData.train_images`;
    `groups` their sizes, `RunData.groups`), kept whole on the device as one array per view."""

    def __init__(self, images, batch: int, seed: int, stream: bool,
                 groups: np.ndarray | None = None):
        self.images, self.batch, self.seed, self.stream = images, batch, seed, stream
        self.groups = groups
        self._whole = None
        if not stream:
            self._whole = (jnp.asarray(images) if isinstance(images, np.ndarray)
                           else [jnp.asarray(im) for im in images])
        self._worker = ThreadPoolExecutor(1, "lgs_jax-views") if stream else None
        self._copies: dict[int, Future] = {}
        self.closed = False  # `close` ran: the worker is ended

    @property
    def held(self) -> list[int]:
        """The steps whose views are on the device or being copied there."""
        return sorted(self._copies)

    def args(self, step: int):
        """(targets, idx) of 0-based `step`."""
        self.prefetch(step)
        return self._copies[step].result()

    def prefetch(self, step: int) -> None:
        """Start putting `step`'s views on the device (the latest two steps' kept)."""
        if step in self._copies:
            return
        self._copies = {k: v for k, v in self._copies.items() if k == step - 1}
        views = views_for_step(step, self.batch, len(self.images), self.seed, self.groups)
        if self.stream:
            self._copies[step] = self._worker.submit(self._copy, views)
            return
        idx, done = jnp.asarray(views), Future()
        if isinstance(self._whole, list):
            done.set_result((_stack(*(self._whole[v] for v in views)), idx))
        else:
            done.set_result((_take(self._whole, idx), idx))
        self._copies[step] = done

    def _copy(self, views):
        """(targets, idx) of `views` from the host (class docstring)."""
        batch = (self.images[views[0]][None] if len(views) == 1
                 else np.stack([self.images[v] for v in views]))
        return jax.device_put(batch), jax.device_put(views)

    def close(self) -> None:
        """End the streaming worker (the copies it made stay valid)."""
        if self._worker is not None:
            self._worker.shutdown()
        self.closed = True


LEVELS = np.arange(256, dtype=np.float32) / np.float32(255)
"""x / 255 in float32 for every 8-bit value x, divided on the host (numpy's IEEE division, as
`io.datasets.as_float` and the image reader divide): XLA rewrites a division by a constant
into a multiplication by its reciprocal, which rounds some values differently."""
LEVELS64 = np.arange(256, dtype=np.float64) / 255.0  # the same in float64


def to_float(images, dtype: str = "float32"):
    """`io.datasets.as_float` on the device (a lookup of `LEVELS`: the same bits), in `dtype`
    (float64: 8-bit values from `LEVELS64`, float32 images widened); float images of `dtype`
    as they are. `step.train_step` applies it to its targets."""
    if images.dtype == jnp.uint8:
        return jnp.asarray(LEVELS64 if dtype == "float64" else LEVELS)[images]
    return images.astype(dtype)


_take = jax.jit(lambda images, idx: images[idx])
_stack = jax.jit(lambda *views: jnp.stack(views))
