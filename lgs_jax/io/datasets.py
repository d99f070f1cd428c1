"""Training datasets of real captures: `load_dataset` and `Dataset`.

Formats, detected in this order in the folder given (or given as the json file itself):
  `transforms.json`        instant-ngp / NeRF (`transforms.py`; lens distortion allowed);
  `transforms_train.json`  NeRF-synthetic (white background; RGBA images);
  `sparse/0/` or `sparse/` a COLMAP model, binary or text (`colmap.py`), images in `images/`.

Each image is read as RGB(A) at its bit depth (8-bit values / 255, 16-bit / 65535;
`views.read_image`), checked against its camera's size, composited over the dataset's background
where it has alpha (image = rgb·a + background·(1 − a)), undistorted to a pinhole camera with no
invalid pixel where its lens has distortion (`undistort.py`, OpenCV), and downscaled by an integer
k with an area filter: the last width % k columns and height % k rows are dropped and each k x k
block is averaged, so that every intrinsic is divided by k exactly (`views.Lens.downscaled`).

Every camera, pose and SfM point is checked as it is read (`transforms.py`, `colmap.py`), and the
downscale against each image's size before any image is read: a `DatasetError` names the file,
the frame, image or point, and the field.

Split: NeRF-synthetic holds out the frames whose id (the last number in the file name) is a
multiple of 10 (lego_train: r_0, r_10, ..., r_90); every other dataset holds out every 8th image in
sorted name order (indices 0, 8, 16, ...), as Mip-NeRF 360 evaluations do.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import os
import re

import numpy as np

from ..scene import Camera
from .colmap import colmap_source, model_folder
from .transforms import transforms_source
from .undistort import undistorter
from .views import DatasetError, Lens, Source, View, bit_depth, read_image

WHITE, BLACK = np.ones(3, np.float32), np.zeros(3, np.float32)


@dataclasses.dataclass(frozen=True, eq=False)
class Dataset:
    """Images and cameras of one capture, ready for training.

    Attributes:
      path: the folder (or json file) it was loaded from.
      names: image file names relative to the image folder, sorted; every field below follows
        this order.
      images: (N, H, W, 3) float32 RGB in [0, 1] (composited over `background` where the files
        have alpha) when all views share one size, as in single-camera captures; otherwise a list
        of (H_i, W_i, 3) arrays. Loaded with dtype=np.uint8: 0..255 instead (`as_float`).
      cameras: one pinhole `Camera` per image (OpenCV axes, undistorted and downscaled intrinsics).
      points, colors: (M, 3) float32 SfM points and their RGB in [0, 1]; (0, 3) where the format
        has none.
      train, test: int64 index arrays of the split (module docstring).
      background: (3,) float32 colour the images were composited over (white for NeRF-synthetic,
        black otherwise): render training views over it.
    """

    path: str
    names: tuple[str, ...]
    images: np.ndarray | list
    cameras: tuple[Camera, ...]
    points: np.ndarray
    colors: np.ndarray
    train: np.ndarray
    test: np.ndarray
    background: np.ndarray

    @property
    def centers(self) -> np.ndarray:
        """(N, 3) camera centres in world space."""
        return np.stack([np.linalg.inv(np.asarray(c.viewmat, np.float64))[:3, 3]
                         for c in self.cameras])

    @property
    def extent(self) -> float:
        """Largest distance of a camera centre from their mean: the scene scale a trainer's
        learning rates use (3DGS's `cameras_extent` is 1.1 times this)."""
        c = self.centers
        return float(np.linalg.norm(c - c.mean(0), axis=1).max())


def _source(path: str) -> Source:
    if os.path.isfile(path) and path.endswith(".json"):
        return transforms_source(path)
    if not os.path.isdir(path):
        raise DatasetError(f"{path}: " + ("not a dataset folder or .json file"
                                          if os.path.exists(path) else "no such file or folder"))
    for name in ("transforms.json", "transforms_train.json"):
        if os.path.isfile(os.path.join(path, name)):
            return transforms_source(os.path.join(path, name))
    if model_folder(path):
        return colmap_source(path)
    raise DatasetError(f"{path}: not a dataset folder (no transforms.json, transforms_train.json,"
                       " sparse/0/cameras.bin or .txt)")


@dataclasses.dataclass(frozen=True)
class DatasetInfo:
    """What a dataset is, read from its model files alone (`dataset_info`): `sfm_points`, its
    SfM point count (0 for a format without them, such as transforms.json); `nerf_synthetic`,
    a NeRF-synthetic folder (white background)."""

    sfm_points: int
    nerf_synthetic: bool


def dataset_info(data) -> DatasetInfo:
    """`DatasetInfo` of `data`: a loaded `Dataset`, or the path `load_dataset` takes (no image
    is opened; `DatasetError` as `load_dataset` for a folder that is not a dataset)."""
    if isinstance(data, Dataset):
        return DatasetInfo(len(data.points), bool(np.all(data.background == 1)))
    source = _source(os.fspath(data))
    return DatasetInfo(len(source.points), bool(source.nerf_synthetic))


def _held_out(names: list[str], nerf_synthetic: bool, where: str) -> np.ndarray:
    if not nerf_synthetic:
        return np.arange(len(names)) % 8 == 0
    ids = []
    for n in names:
        digits = re.findall(r"\d+", os.path.basename(n))
        if not digits:
            raise DatasetError(f"{where}: frame {n!r} has no number in its name (NeRF-synthetic "
                               "splits by frame id)")
        ids.append(int(digits[-1]))
    return np.asarray(ids) % 10 == 0


def block_mean(image: np.ndarray, k: int) -> np.ndarray:
    """(H // k, W // k, C) float64 mean of each k x k block of an (H, W, C) image, after
    dropping the last H % k rows and W % k columns (the downscale of `load_dataset`)."""
    h, w = image.shape[0] // k, image.shape[1] // k
    return image[:h * k, :w * k].reshape(h, k, w, k, image.shape[2]).mean((1, 3),
                                                                           dtype=np.float64)


def _downscale(image: np.ndarray, k: int) -> np.ndarray:
    """`block_mean` in float32 (the image itself for k = 1)."""
    if k == 1:
        return image
    return block_mean(image, k).astype(np.float32)


def _prepare(view: View, source: Source, background, undistorters, k,
             dtype) -> tuple[np.ndarray, Lens]:
    """The image of one view, composited, undistorted and downscaled, with its final lens, as
    `dtype` (uint8: rounded to the nearest of x/255)."""
    image = read_image(view.path, source.file)
    lens = view.lens
    if image.shape[:2] != (lens.height, lens.width):
        raise DatasetError(f"{view.path}: image is {image.shape[1]}x{image.shape[0]} pixels but "
                           f"its camera in {source.lens_file} is {lens.width}x{lens.height}")
    if image.shape[2] == 4:
        image = image[..., :3] * image[..., 3:] + background * (1 - image[..., 3:])
    if lens.distorted:
        lens, undistort = undistorters[lens]
        image = undistort(image)
    image = _downscale(image, k)
    if dtype == np.uint8:
        image = np.round(image * np.float32(255)).astype(np.uint8)
    return image, lens.downscaled(k)


def _check_downscale(views: list[View], undistorters: dict, k: int) -> None:
    """Refuse a downscale that leaves an image (undistorted where its lens has distortion) with
    no pixel."""
    for v in views:
        lens = undistorters[v.lens][0] if v.lens.distorted else v.lens
        if lens.width < k or lens.height < k:
            after = " after undistortion" if v.lens.distorted else ""
            raise DatasetError(f"{v.path}: downscale {k} is larger than the image ({lens.width}x"
                               f"{lens.height} pixels{after})")


def _stack(images: list[np.ndarray]) -> np.ndarray | list:
    if len({im.shape for im in images}) > 1:
        return images
    out = np.empty((len(images),) + images[0].shape, images[0].dtype)
    for i in range(len(images)):
        out[i], images[i] = images[i], None  # one copy in memory at a time
    return out


def as_float(images) -> np.ndarray:
    """Images of a `Dataset` as float32 in [0, 1]: uint8 ones divided by 255 in float32 (the
    bits `load_dataset` gives without dtype=np.uint8, where no compositing, undistortion or
    downscale rounded them), float32 ones unchanged."""
    images = np.asarray(images)
    return images.astype(np.float32) / np.float32(255) if images.dtype == np.uint8 else images


def _dtype(dtype, views: list[View], listed_in: str):
    """np.float32 or np.uint8 for `load_dataset`'s `dtype`: "auto" is np.uint8 where every image
    file is 8-bit (`views.bit_depth`), np.float32 otherwise."""
    if isinstance(dtype, str) and dtype == "auto":
        eight = all(bit_depth(v.path, listed_in) == 8 for v in views)
        return np.dtype(np.uint8) if eight else np.dtype(np.float32)
    return np.dtype(dtype)


def load_dataset(path, *, downscale: int = 1, dtype=np.float32) -> Dataset:
    """Load a COLMAP, instant-ngp/NeRF or NeRF-synthetic dataset (module docstring).

    `downscale`: integer factor k >= 1; images are averaged over k x k blocks and the cameras'
    intrinsics divided by k (sizes rounded down: width // k, height // k).
    `dtype`: np.float32 (default), or np.uint8 to hold the images in a quarter of the memory
    (12 bytes a pixel against 3: 30 GB against 7.5 for 300 views at 4K), each value rounded to
    the nearest of x/255 after compositing, undistortion and downscaling (exact where none of
    them applies: `as_float` then gives the float32 images' bits); or "auto": np.uint8 where
    every image file is 8-bit, np.float32 where one has 16 bits.
    Raises `DatasetError` (a `ValueError`) naming the file and the problem for a dataset that
    cannot be loaded, and `ImportError` if a distorted camera needs OpenCV and it is missing
    (install the `data` extra: pip install 'lgs_jax[data]').
    """
    if isinstance(downscale, bool) or not isinstance(downscale, (int, np.integer)) \
            or downscale < 1:
        raise ValueError(f"downscale: expected an integer >= 1, got {downscale!r}")
    if not (isinstance(dtype, str) and dtype == "auto"):
        try:
            dtype = np.dtype(dtype)
        except TypeError:
            dtype = None
        if dtype not in (np.float32, np.uint8):
            raise ValueError(f"dtype: expected np.float32, np.uint8 or \"auto\", got "
                             f"{dtype!r}")
    path = os.fspath(path)
    source = _source(path)
    views = sorted(source.views, key=lambda v: v.name)
    names = [v.name for v in views]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise DatasetError(f"{source.file}: images listed more than once: {dupes[:5]}")
    background = WHITE if source.nerf_synthetic else BLACK
    dtype = _dtype(dtype, views, source.file)
    undistorters = {v.lens: undistorter(v.lens, source.lens_file) for v in views
                    if v.lens.distorted}
    _check_downscale(views, undistorters, int(downscale))
    with concurrent.futures.ThreadPoolExecutor(min(8, os.cpu_count() or 1)) as pool:
        done = list(pool.map(lambda v: _prepare(v, source, background, undistorters,
                                                int(downscale), dtype), views))
    held = _held_out(names, source.nerf_synthetic, source.file)
    return Dataset(path=path, names=tuple(names), images=_stack([im for im, _ in done]),
                   cameras=tuple(lens.camera(v.viewmat) for v, (_, lens) in zip(views, done)),
                   points=source.points.astype(np.float32),
                   colors=source.colors.astype(np.float32) / np.float32(255),
                   train=np.flatnonzero(~held), test=np.flatnonzero(held), background=background)
