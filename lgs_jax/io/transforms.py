"""instant-ngp / NeRF transforms.json (and NeRF-synthetic transforms_train.json) as views.

Keys, each either at the top level (shared) or in a frame (that frame's, overriding):
  `w`, `h`          image size (default: read from the image file);
  `fl_x`, `fl_y`    focal lengths in pixels; else `camera_angle_x` / `camera_angle_y`, the full
                    field of view in radians: fl_x = 0.5·w / tan(0.5·camera_angle_x); fl_y
                    defaults to fl_x;
  `cx`, `cy`        principal point (default w/2, h/2; pixel centres at +0.5 as in COLMAP, whose
                    values instant-ngp's colmap2nerf copies);
  `k1 k2 p1 p2 k3`  OpenCV radial-tangential distortion (`views.Lens`; default 0).
Fisheye models (`is_fisheye`, `camera_model` OPENCV_FISHEYE, `k4`) are not supported.
Each frame has `file_path` (relative to the json's folder; NeRF-synthetic leaves off '.png') and
`transform_matrix`, a 4x4 camera-to-world matrix with OpenGL camera axes (x right, y up, looking
down −z); negating its camera y and z columns gives OpenCV axes, and its inverse is the viewmat.

Every field is checked as it is read (`fields.py`): focal lengths finite and > 0, fields of view
in (0, π), sizes positive whole numbers, cx, cy and distortion finite, `transform_matrix` finite
with last row (0, 0, 0, 1) and a rotation (orthonormal to `scene.ORTHO_TOL`, determinant +1: no
scale or shear). A `DatasetError` names the file, the frame (index and file_path) and the field.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..scene import ORTHO_TOL, rotation_problem
from .fields import field_of_view, matrix, number, pixels, positive, read_json
from .views import DISTORTION, DatasetError, Lens, Source, View, image_size

EXTENSIONS = (".png", ".jpg", ".jpeg", ".JPG", ".PNG")


def _image_path(root: str, file_path: str) -> str:
    path = os.path.normpath(os.path.join(root, file_path))
    if os.path.splitext(path)[1] or os.path.exists(path):
        return path
    return next((path + e for e in EXTENSIONS if os.path.exists(path + e)), path + ".png")


def _focal(fields, key: str, angle: str, side: int, where: str) -> float | None:
    """The focal length `key` in pixels, else 0.5·side / tan(0.5·`angle`), else None."""
    if key in fields:
        return positive(fields, key, where)
    if angle in fields:
        return 0.5 * side / math.tan(0.5 * field_of_view(fields, angle, where))
    return None


def _lens(meta: dict, frame: dict, image: str, path: str, where: str) -> Lens:
    """The intrinsics of one frame: its own keys over the shared (top-level) ones."""
    fields = {**meta, **frame}
    if fields.get("is_fisheye") or fields.get("camera_model") not in (None, "OPENCV", "PINHOLE") \
            or fields.get("k4"):
        raise DatasetError(f"{where}: unsupported camera model (fisheye); supported: pinhole "
                           "with k1 k2 p1 p2 k3")
    if "w" in fields and "h" in fields:
        w, h = pixels(fields, "w", where), pixels(fields, "h", where)
    else:
        w, h = image_size(image, path)
    fx = _focal(fields, "fl_x", "camera_angle_x", w, where)
    if fx is None:
        raise DatasetError(f"{where}: no focal length (fl_x or camera_angle_x)")
    fy = _focal(fields, "fl_y", "camera_angle_y", h, where) or fx
    cx = number(fields, "cx", where) if "cx" in fields else w / 2
    cy = number(fields, "cy", where) if "cy" in fields else h / 2
    dist = tuple(number(fields, k, where) if k in fields else 0.0 for k in DISTORTION)
    return Lens(fx, fy, cx, cy, w, h, dist)


def _viewmat(frame: dict, where: str) -> np.ndarray:
    """World-to-camera (OpenCV axes) of a frame's camera-to-world `transform_matrix`."""
    c2w = matrix(frame, "transform_matrix", (4, 4), where)
    if np.max(np.abs(c2w[3] - [0, 0, 0, 1])) > ORTHO_TOL:
        raise DatasetError(f"{where}: transform_matrix: last row must be (0, 0, 0, 1), got "
                           f"{c2w[3]}")
    problem = rotation_problem(c2w[:3, :3])
    if problem:
        raise DatasetError(f"{where}: transform_matrix: rotation {problem}")
    c2w[:3, 1:3] *= -1  # OpenGL camera axes -> OpenCV (y down, z forward)
    return np.linalg.inv(c2w)


def _view(meta: dict, frame, i: int, root: str, path: str) -> View:
    if not isinstance(frame, dict):
        raise DatasetError(f"{path}: frame {i}: expected an object, got {type(frame).__name__}")
    if not isinstance(frame.get("file_path"), str):
        raise DatasetError(f"{path}: frame {i}: missing 'file_path' (a string)")
    where = f"{path}: frame {i} ({frame['file_path']})"
    viewmat = _viewmat(frame, where)
    image = _image_path(root, frame["file_path"])
    name = os.path.relpath(image, root).replace(os.sep, "/")
    return View(name, image, viewmat, _lens(meta, frame, image, path, where))


def transforms_views(meta, path: str) -> list[View]:
    """The views of the parsed transforms.json `meta` read from `path`, in file order; every
    field is checked (a `DatasetError` names the file, the frame and the field)."""
    frames = meta.get("frames") if isinstance(meta, dict) else None
    if not frames or not isinstance(frames, list):
        raise DatasetError(f"{path}: no frames (expected a non-empty 'frames' list)")
    return [_view(meta, frame, i, os.path.dirname(path), path) for i, frame in enumerate(frames)]


def transforms_source(path: str) -> Source:
    """Views of a transforms.json; a file named transforms_train.json is NeRF-synthetic."""
    views = transforms_views(read_json(path), path)
    empty = np.zeros((0, 3))
    return Source(path, path, views, empty, empty.astype(np.uint8),
                  nerf_synthetic=os.path.basename(path) == "transforms_train.json")
