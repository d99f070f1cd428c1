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
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from .views import DISTORTION, DatasetError, Lens, Source, View, image_size

EXTENSIONS = (".png", ".jpg", ".jpeg", ".JPG", ".PNG")


def _image_path(root: str, file_path: str) -> str:
    path = os.path.normpath(os.path.join(root, file_path))
    if os.path.splitext(path)[1] or os.path.exists(path):
        return path
    return next((path + e for e in EXTENSIONS if os.path.exists(path + e)), path + ".png")


def _lens(meta: dict, frame: dict, path: str, where: str) -> Lens:
    get = lambda key: frame.get(key, meta.get(key))
    if get("is_fisheye") or get("camera_model") not in (None, "OPENCV", "PINHOLE") or get("k4"):
        raise DatasetError(f"{where}: frame {frame['file_path']!r} has an unsupported camera "
                           f"model (fisheye); supported: pinhole with k1 k2 p1 p2 k3")
    w, h = get("w"), get("h")
    if w is None or h is None:
        w, h = image_size(path, where)
    if get("fl_x") is not None:
        fx = float(get("fl_x"))
    elif get("camera_angle_x") is not None:
        fx = 0.5 * w / math.tan(0.5 * get("camera_angle_x"))
    else:
        raise DatasetError(f"{where}: no focal length (fl_x or camera_angle_x) for frame "
                           f"{frame['file_path']!r}")
    if get("fl_y") is not None:
        fy = float(get("fl_y"))
    elif get("camera_angle_y") is not None:
        fy = 0.5 * h / math.tan(0.5 * get("camera_angle_y"))
    else:
        fy = fx
    cx, cy = get("cx"), get("cy")
    return Lens(fx, fy, float(w / 2 if cx is None else cx), float(h / 2 if cy is None else cy),
                int(w), int(h), tuple(float(get(k) or 0.0) for k in DISTORTION))


def _view(meta: dict, frame: dict, root: str, where: str) -> View:
    path = _image_path(root, frame["file_path"])
    c2w = np.asarray(frame["transform_matrix"], np.float64)
    if c2w.shape != (4, 4) or not np.all(np.isfinite(c2w)):
        raise ValueError("transform_matrix is not a finite 4x4 matrix")
    c2w[:3, 1:3] *= -1  # OpenGL camera axes -> OpenCV (y down, z forward)
    name = os.path.relpath(path, root).replace(os.sep, "/")
    return View(name, path, np.linalg.inv(c2w), _lens(meta, frame, path, where))


def transforms_source(path: str) -> Source:
    """Views of a transforms.json; a file named transforms_train.json is NeRF-synthetic."""
    try:
        with open(path, encoding="utf-8") as f:
            meta = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path}: cannot read ({e})") from None
    frames = meta.get("frames") if isinstance(meta, dict) else None
    if not frames or not isinstance(frames, list):
        raise DatasetError(f"{path}: no frames (expected a non-empty 'frames' list)")
    root, views = os.path.dirname(path), []
    for i, frame in enumerate(frames):
        try:
            views.append(_view(meta, frame, root, path))
        except DatasetError:
            raise
        except (AttributeError, KeyError, TypeError, ValueError) as e:
            raise DatasetError(f"{path}: frame {i} is malformed ({type(e).__name__}: {e})") \
                from None
    empty = np.zeros((0, 3))
    return Source(path, path, views, empty, empty.astype(np.uint8),
                  nerf_synthetic=os.path.basename(path) == "transforms_train.json")
