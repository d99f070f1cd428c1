"""What the dataset format readers produce: views (image file, pose, lens) and image helpers.

Every format (COLMAP, transforms.json) is read into a `Source`: one `View` per image, with the
world-to-camera pose in OpenCV axes (x right, y down, z forward) and a `Lens`. `datasets.py` turns
a `Source` into a `Dataset` (images read, undistorted, downscaled).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..scene import Camera

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

    def camera(self, viewmat) -> Camera:
        """The pinhole `Camera` of this lens at world-to-camera `viewmat` (float32 leaves). A
        distorted lens has no pinhole camera: undistort it first (`undistort.undistorted_lens`)."""
        if self.distorted:
            raise ValueError(f"lens: distortion {self.dist} has no pinhole camera; undistort it")
        f32 = np.float32
        return Camera(viewmat=np.asarray(viewmat).astype(f32), fx=f32(self.fx), fy=f32(self.fy),
                      cx=f32(self.cx), cy=f32(self.cy), width=self.width, height=self.height)


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


def opencv(where: str, need: str):
    """The cv2 module; `ImportError` naming `where` and what `need`s it if OpenCV is missing."""
    try:
        import cv2
    except ImportError:
        raise ImportError(f"{where}: {need} needs OpenCV: pip install 'lgs_jax[data]' "
                          "(opencv-python-headless)") from None
    return cv2


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


def bit_depth(path: str, listed_in: str) -> int:
    """Bits per channel of an image file, from its header: 16 for 16-bit PNG and 16-bit grey
    images, 8 otherwise (the depths `read_image` reads)."""
    with _open(path, listed_in) as im:
        if im.mode.startswith("I;16") or (im.format == "PNG" and _png_bit_depth(path) == 16):
            return 16
        return 8


def _png_bit_depth(path: str) -> int | None:
    """The bit depth in a PNG file's IHDR chunk (None if `path` is not a PNG file)."""
    with open(path, "rb") as f:
        head = f.read(26)
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return head[24]


def _png16(path: str) -> np.ndarray:
    """(H, W, 3|4) uint16 RGB(A) of a 16-bit PNG, read by OpenCV (Pillow reads 16-bit colour
    as 8 bits)."""
    cv2 = opencv(path, "reading a 16-bit colour PNG image")
    pixels = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if pixels is None or pixels.dtype != np.uint16:
        raise DatasetError(f"{path}: cannot read the 16-bit PNG image")
    if pixels.ndim == 2:
        return np.repeat(pixels[..., None], 3, -1)
    return pixels[..., [2, 1, 0, 3][:pixels.shape[2]]]  # BGR(A) -> RGB(A)


def _pixels(im, path: str) -> np.ndarray:
    """(H, W, 3 or 4) uint8 or uint16 pixels of an open Pillow image, at the file's bit depth."""
    if im.mode.startswith("I;16") and "transparency" not in im.info:
        return np.repeat(np.asarray(im).astype(np.uint16)[..., None], 3, -1)  # 16-bit grey
    if im.format == "PNG" and _png_bit_depth(path) == 16:
        return _png16(path)
    if im.mode in ("I", "F") or im.mode.startswith("I;16"):
        raise DatasetError(f"{path}: unsupported pixel format (Pillow mode {im.mode}); use 8- or "
                           "16-bit images")
    has_alpha = im.mode in ("RGBA", "LA", "PA") or "transparency" in im.info
    return np.asarray(im.convert("RGBA" if has_alpha else "RGB"))


def read_image(path: str, listed_in: str) -> np.ndarray:
    """(H, W, 3) or, where the file has alpha, (H, W, 4) float32 in [0, 1]: 8-bit values / 255,
    16-bit ones / 65535 (each the nearest float32 of the quotient)."""
    with _open(path, listed_in) as im:
        try:
            pixels = _pixels(im, path)
        except OSError as e:
            raise DatasetError(f"{path}: cannot read the image ({e})") from None
    scale = np.float32(65535 if pixels.dtype == np.uint16 else 255)
    return pixels.astype(np.float32) / scale
