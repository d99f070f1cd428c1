"""Undistortion of images with lens distortion to pinhole images with no invalid pixel (OpenCV).

The pinhole camera keeps the focal lengths fx, fy (the image keeps its resolution at the centre)
and is cropped to the largest axis-aligned rectangle of the normalised image plane that the
distorted image covers everywhere:

1. Points every half pixel along the four edges of the distorted image (its outer boundary,
   u in [0, W], v in [0, H]) are undistorted (OpenCV's iterative inverse of `Lens`'s model, run to
   convergence). The rectangle is [max x of the left edge, min x of the right edge] x [max y of the
   top edge, min y of the bottom edge]: inside the boundary for barrel and pincushion distortion
   alike (this is COLMAP's rule for undistortion with no blank pixels).
2. The new image is W' = floor(fx·(x1 − x0)) by H' = floor(fy·(y1 − y0)) pixels, centred on the
   rectangle: cx' = W'/2 − fx·(x0 + x1)/2, cy' likewise.
3. Each new pixel centre is mapped through the distortion model (`cv2.initUndistortRectifyMap`,
   the exact forward model) and sampled bilinearly (`cv2.remap`). The maps are checked to lie
   within the distorted image, so no pixel of the result comes from outside it (the outer
   half pixel of the border repeats the border pixel).

OpenCV is an optional dependency (the `data` extra); only distorted cameras need it.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from .views import DatasetError, Lens, opencv


def _matrix(lens: Lens) -> np.ndarray:
    """OpenCV's camera matrix: its pixel centres are at integer coordinates, ours at +0.5."""
    return np.array([[lens.fx, 0, lens.cx - 0.5], [0, lens.fy, lens.cy - 0.5], [0, 0, 1]],
                    np.float64)


def _valid_rectangle(cv2, lens: Lens) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) in the normalised image plane (step 1 of the module docstring)."""
    w, h = lens.width, lens.height
    u, v = np.linspace(0, w, 2 * w + 1), np.linspace(0, h, 2 * h + 1)
    edges = [(np.zeros_like(v), v), (np.full_like(v, w), v), (u, np.zeros_like(u)),
             (u, np.full_like(u, h))]
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    left, right, top, bottom = [
        cv2.undistortPoints(np.stack([a, b], -1)[:, None] - 0.5, _matrix(lens),
                            np.asarray(lens.dist), criteria=criteria)[:, 0] for a, b in edges]
    return left[:, 0].max(), right[:, 0].min(), top[:, 1].max(), bottom[:, 1].min()


def undistorter(lens: Lens, where: str) -> tuple[Lens, Callable[[np.ndarray], np.ndarray]]:
    """(pinhole lens, function undistorting an (H, W, C) float32 image taken through `lens`).

    `where` names the file the camera comes from (for messages). Raises `DatasetError` if the
    distortion is too strong to give a valid rectangle, `ImportError` if OpenCV is missing.
    """
    cv2 = opencv(where, "the camera has lens distortion and undistorting it")
    x0, x1, y0, y1 = _valid_rectangle(cv2, lens)
    w, h = int(np.floor(lens.fx * (x1 - x0))), int(np.floor(lens.fy * (y1 - y0)))
    if not (np.all(np.isfinite([x0, x1, y0, y1])) and w > 0 and h > 0):
        raise DatasetError(f"{where}: lens distortion {lens.dist} leaves no valid image")
    new = dataclasses.replace(lens, cx=float(w / 2 - lens.fx * (x0 + x1) / 2),
                              cy=float(h / 2 - lens.fy * (y0 + y1) / 2), width=w, height=h,
                              dist=(0.0,) * 5)
    mx, my = cv2.initUndistortRectifyMap(_matrix(lens), np.asarray(lens.dist), None,
                                         _matrix(new), (w, h), cv2.CV_32FC1)
    tol = 1e-3  # float32 maps; the border repeats, so a sample this far out is still valid
    if not (mx.min() >= -0.5 - tol and mx.max() <= lens.width - 0.5 + tol
            and my.min() >= -0.5 - tol and my.max() <= lens.height - 0.5 + tol):
        raise DatasetError(f"{where}: lens distortion {lens.dist} too strong to undistort "
                           "without invalid pixels")

    def apply(image: np.ndarray) -> np.ndarray:
        return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    return new, apply
