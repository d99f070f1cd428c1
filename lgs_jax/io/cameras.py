"""Camera files: INRIA cameras.json (read and written) and NeRF-synthetic transforms.json.

Every field is checked as it is read: a missing or malformed one raises `ValueError` naming the
file, the camera (or frame) and the field.
"""

from __future__ import annotations

import json
import math
import numbers
import os

import numpy as np

from ..scene import ORTHO_TOL, Camera, check_size, rotation_problem


def _number(c: dict, key: str, where: str) -> float:
    """`c[key]` as a finite float; raise naming `where` and the field if missing or not one."""
    if key not in c:
        raise ValueError(f"{where}: missing {key!r}")
    v = c[key]
    if not isinstance(v, numbers.Real) or isinstance(v, bool) or not math.isfinite(v):
        raise ValueError(f"{where}: {key} must be a finite number, got {v!r}")
    return float(v)


def _pixels(c: dict, key: str, where: str) -> int:
    """`c[key]` as a positive whole number of pixels (1280 or 1280.0, not 1280.7 or "1280")."""
    v = _number(c, key, where)
    if v <= 0 or not v.is_integer():
        raise ValueError(f"{where}: {key} must be a positive whole number of pixels, got "
                         f"{c[key]!r}")
    return int(v)


def _matrix(c: dict, key: str, shape: tuple, where: str) -> np.ndarray:
    """`c[key]` as a float64 array of `shape` with finite entries."""
    if key not in c:
        raise ValueError(f"{where}: missing {key!r}")
    try:
        m = np.asarray(c[key], np.float64)
    except (TypeError, ValueError):
        m = None
    if m is None or m.shape != shape or not np.all(np.isfinite(m)):
        raise ValueError(f"{where}: {key} must be {'x'.join(map(str, shape))} finite numbers, "
                         f"got {c[key]!r}")
    return m


def _inria_camera(c, where: str) -> Camera:
    """`rotation` holds the camera-to-world rotation (rows), `position` the camera centre."""
    if not isinstance(c, dict):
        raise ValueError(f"{where}: expected an object, got {type(c).__name__}")
    rot = _matrix(c, "rotation", (3, 3), where)
    problem = rotation_problem(rot)
    if problem:
        raise ValueError(f"{where}: rotation {problem}")
    pos = _matrix(c, "position", (3,), where)
    width, height = _pixels(c, "width", where), _pixels(c, "height", where)
    view = np.eye(4)
    view[:3, :3] = rot.T
    view[:3, 3] = -rot.T @ pos
    cx = _number(c, "cx", where) if "cx" in c else width / 2
    cy = _number(c, "cy", where) if "cy" in c else height / 2
    return Camera(viewmat=view.astype(np.float32), fx=np.float32(_number(c, "fx", where)),
                  fy=np.float32(_number(c, "fy", where)), cx=np.float32(cx), cy=np.float32(cy),
                  width=width, height=height)


def _image_size(path: str) -> tuple[int, int]:
    import matplotlib.image

    h, w = matplotlib.image.imread(path).shape[:2]
    return w, h


def _nerf_size(frames: list, root: str, width, height, path: str) -> tuple[int, int]:
    """The image size: (width, height) if both are given, else the first frame's image size,
    with a single given side scaled to keep the image's aspect ratio."""
    if width is not None and height is not None:
        return width, height
    if not frames:
        raise ValueError(f"{path}: 'frames' is empty, so there is no image to read the size "
                         "from; pass width and height")
    if not isinstance(frames[0], dict) or not isinstance(frames[0].get("file_path"), str):
        raise ValueError(f"{path}: frame 0: missing 'file_path' (needed for the image size)")
    first = os.path.join(root, frames[0]["file_path"])
    if not os.path.splitext(first)[1]:
        first += ".png"
    w, h = _image_size(first)
    if width is not None:
        return width, max(1, round(h * width / w))
    if height is not None:
        return max(1, round(w * height / h)), height
    return w, h


def _nerf_viewmat(fr, where: str) -> np.ndarray:
    """World-to-camera (OpenCV axes) of a frame's Blender/OpenGL `transform_matrix`."""
    if not isinstance(fr, dict):
        raise ValueError(f"{where}: expected an object, got {type(fr).__name__}")
    c2w = _matrix(fr, "transform_matrix", (4, 4), where)
    if np.max(np.abs(c2w[3] - [0, 0, 0, 1])) > ORTHO_TOL:
        raise ValueError(f"{where}: transform_matrix: last row must be (0, 0, 0, 1), got {c2w[3]}")
    problem = rotation_problem(c2w[:3, :3])
    if problem:
        raise ValueError(f"{where}: transform_matrix: rotation {problem}")
    c2w[:3, 1:3] *= -1  # Blender/OpenGL camera axes -> OpenCV (y down, z forward)
    return np.linalg.inv(c2w)


def _nerf_cameras(meta: dict, root: str, width, height, path: str) -> list[Camera]:
    """One camera per frame of a transforms.json; focal length from camera_angle_x (and
    camera_angle_y if given) at the image size (`_nerf_size`)."""
    frames = meta["frames"]
    if not isinstance(frames, list):
        raise ValueError(f"{path}: 'frames' must be a list, got {type(frames).__name__}")
    angle_x = _number(meta, "camera_angle_x", path)
    width, height = _nerf_size(frames, root, width, height, path)
    fx = 0.5 * width / math.tan(0.5 * angle_x)
    fy = (0.5 * height / math.tan(0.5 * _number(meta, "camera_angle_y", path))
          if "camera_angle_y" in meta else fx)
    views = [_nerf_viewmat(fr, f"{path}: frame {i}") for i, fr in enumerate(frames)]
    return [Camera(viewmat=view.astype(np.float32), fx=np.float32(fx), fy=np.float32(fy),
                   cx=np.float32(width / 2), cy=np.float32(height / 2), width=int(width),
                   height=int(height)) for view in views]


def _read_json(path: str):
    """The parsed JSON of `path`; malformed JSON raises `ValueError` naming the file and line."""
    with open(path) as f:
        try:
            return json.load(f)
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not valid JSON: {e}") from None


def load_cameras(path, *, width: int | None = None, height: int | None = None) -> list[Camera]:
    """Cameras from an INRIA cameras.json (list of views) or a NeRF transforms.json.

    `width`/`height` resize INRIA cameras with `Camera.resized`: one of them keeps each camera's
    aspect ratio; both with another aspect ratio scale the view to cover the new size and crop
    its centre (never stretched). For NeRF files they give the image size (camera_angle_x sets
    the focal length at any size); a missing one is read from the first frame's image, keeping
    its aspect ratio. Raises `ValueError` naming the file and field for malformed content.
    """
    for name, v in (("width", width), ("height", height)):
        if v is not None:
            check_size(name, v)
    path = os.fspath(path)
    meta = _read_json(path)
    if isinstance(meta, list):
        return [_inria_camera(c, f"{path}: camera {i}").resized(width, height)
                for i, c in enumerate(meta)]
    if isinstance(meta, dict) and "frames" in meta:
        return _nerf_cameras(meta, os.path.dirname(path), width, height, path)
    raise ValueError(f"{path}: neither an INRIA cameras.json list nor a transforms.json")


def save_cameras(path, cameras, names=None) -> None:
    """Write `cameras` as an INRIA cameras.json (what 3DGS writes beside its scene, and
    `load_cameras` reads back): per camera id, img_name (`names[i]`, else its index), width,
    height, position (the camera centre), rotation (camera-to-world, rows), fx, fy, cx, cy, in
    float64 from the cameras' float32."""
    out = []
    for i, cam in enumerate(cameras):
        view = np.asarray(cam.viewmat, np.float64)
        rot = view[:3, :3].T
        out.append(dict(id=i, img_name=str(names[i]) if names is not None else str(i),
                        width=int(cam.width), height=int(cam.height),
                        position=(-rot @ view[:3, 3]).tolist(), rotation=rot.tolist(),
                        fx=float(cam.fx), fy=float(cam.fy), cx=float(cam.cx),
                        cy=float(cam.cy)))
    with open(os.fspath(path), "w") as f:
        json.dump(out, f, indent=1)
