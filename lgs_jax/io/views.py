"""What the dataset format readers produce: views (image file, pose, lens) and image helpers.

Every format (COLMAP, transforms.json) is read into a `Source`: one `View` per image, with the
world-to-camera pose in OpenCV axes (x right, y down, z forward) and a `Lens`. `dataset.py` turns a
`Source` into a `Dataset` (images read, undistorted, downscaled).
"""

from __future__ import annotations

import dataclasses

import numpy as np

DISTORTION = ("k1", "k2", "p1", "p2", "k3")


class DatasetError(ValueError):
    """A dataset that cannot be loaded; the message names the file and the problem."""


@dataclasses.dataclass(frozen=True)
class Lens:
    """Intrinsics of one image: a pinhole camera with OpenCV's radial-tangential distortion.

    A camera-space point (X, Y, Z) has normalised coordinates x = X/Z, y = Y/Z; with
    r² = x² + y² the lens moves it to

        x_d = x·(1 + k1·r² + k2·r⁴ + k3·r⁶) + 2·p1·x·y + p2·(r² + 2·x²)
        y_d = y·(1 + k1·r² + k2·r⁴ + k3·r⁶) + p1·(r² + 2·y²) + 2·p2·x·y

    and it lands at pixel coordinates u = fx·x_d + cx, v = fy·y_d + cy, where pixel (i, j) (row i,
    column j) has its centre at (j + 0.5, i + 0.5) (COLMAP's and lgs_jax's convention; OpenCV's
    own functions put it at (j, i)). `dist` = (k1, k2, p1, p2, k3); all zero is a pinhole.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: tuple[float, ...] = (0.0,) * 5

    @property
    def distorted(self) -> bool:
        return any(d != 0 for d in self.dist)

    def downscaled(self, k: int) -> "Lens":
        """The lens of the image cut to (width // k)·k x (height // k)·k pixels (the last
        columns and rows dropped) and averaged over k x k blocks: new pixel j covers old pixels
        k·j .. k·j + k − 1, so its centre k·(j + 0.5) is old coordinate k·(new coordinate), and
        every intrinsic is divided by k exactly."""
        return dataclasses.replace(self, fx=self.fx / k, fy=self.fy / k, cx=self.cx / k,
                                   cy=self.cy / k, width=self.width // k,
                                   height=self.height // k)


@dataclasses.dataclass(frozen=True, eq=False)
class View:
    """One image: `name` (its path relative to the image folder, '/'-separated), `path` (the file),
    `viewmat` ((4, 4) float64 world-to-camera, OpenCV axes) and `lens`."""

    name: str
    path: str
    viewmat: np.ndarray
    lens: Lens


@dataclasses.dataclass(frozen=True, eq=False)
class Source:
    """A dataset as read from its files, before any image is loaded.

    `file`: the model file that lists the views and `lens_file` the one that defines their
    cameras (the same file for transforms.json; for messages); `points` (M, 3) float64 and
    `colors` (M, 3) uint8: SfM points, (0, 3) where the format has none; `nerf_synthetic`: a
    NeRF-synthetic folder (white background, frame ids held out every 10th).
    """

    file: str
    lens_file: str
    views: list[View]
    points: np.ndarray
    colors: np.ndarray
    nerf_synthetic: bool = False


def _open(path: str, listed_in: str):
    from PIL import Image, UnidentifiedImageError

    try:
        return Image.open(path)
    except FileNotFoundError:
        raise DatasetError(f"{path}: image not found (listed in {listed_in})") from None
    except (OSError, UnidentifiedImageError) as e:
        raise DatasetError(f"{path}: cannot read the image ({e})") from None


def image_size(path: str, listed_in: str) -> tuple[int, int]:
    """(width, height) of an image file, from its header."""
    with _open(path, listed_in) as im:
        return im.size


def read_image(path: str, listed_in: str) -> np.ndarray:
    """(H, W, 3) or, where the file has alpha, (H, W, 4) float32 in [0, 1]."""
    with _open(path, listed_in) as im:
        try:
            has_alpha = im.mode in ("RGBA", "LA", "PA") or "transparency" in im.info
            rgb = np.asarray(im.convert("RGBA" if has_alpha else "RGB"))
        except OSError as e:
            raise DatasetError(f"{path}: cannot read the image ({e})") from None
    return rgb.astype(np.float32) / np.float32(255)
