"""Camera files: INRIA cameras.json (read and written) and instant-ngp / NeRF transforms.json
(read with the dataset loader's parser, `transforms.py`).

Every field is checked as it is read: a missing or malformed one raises `DatasetError` (a
`ValueError`) naming the file, the camera (or frame) and the field.
"""

from __future__ import annotations

import json
import os

import numpy as np

from ..scene import Camera, check_size, rotation_problem
from .fields import matrix, number, pixels, positive, read_json
from .transforms import transforms_views
from .undistort import undistorter
from .views import DatasetError


def _inria_camera(c, where: str) -> Camera:
    """`rotation` holds the camera-to-world rotation (rows), `position` the camera centre."""
    if not isinstance(c, dict):
        raise DatasetError(f"{where}: expected an object, got {type(c).__name__}")
    rot = matrix(c, "rotation", (3, 3), where)
    problem = rotation_problem(rot)
    if problem:
        raise DatasetError(f"{where}: rotation {problem}")
    pos = matrix(c, "position", (3,), where)
    width, height = pixels(c, "width", where), pixels(c, "height", where)
    view = np.eye(4)
    view[:3, :3] = rot.T
    view[:3, 3] = -rot.T @ pos
    cx = number(c, "cx", where) if "cx" in c else width / 2
    cy = number(c, "cy", where) if "cy" in c else height / 2
    return Camera(viewmat=view.astype(np.float32), fx=np.float32(positive(c, "fx", where)),
                  fy=np.float32(positive(c, "fy", where)), cx=np.float32(cx), cy=np.float32(cy),
                  width=width, height=height)


def _transforms_cameras(meta: dict, path: str) -> list[Camera]:
    """The cameras a dataset loaded from this transforms.json trains with at downscale 1: the
    undistorted pinhole camera (`undistort.undistorter`) where a frame's lens has distortion."""
    pinhole = {}
    cameras = []
    for view in transforms_views(meta, path):
        if view.lens not in pinhole:
            pinhole[view.lens] = undistorter(view.lens, path)[0] if view.lens.distorted \
                else view.lens
        cameras.append(pinhole[view.lens].camera(view.viewmat))
    return cameras


def load_cameras(path, *, width: int | None = None, height: int | None = None) -> list[Camera]:
    """Cameras from an INRIA cameras.json (list of views) or a NeRF transforms.json, in file order.

    transforms.json is read as `load_dataset` reads it (`transforms.py`: per-frame intrinsics,
    image sizes from w/h or the image files), and a lens with distortion gives the undistorted
    pinhole camera the dataset trains with (this needs OpenCV, the `data` extra), so a scene
    trained on the capture renders at its training views.
    `width`/`height` resize the cameras with `Camera.resized`: one of them keeps each camera's
    aspect ratio; both with another aspect ratio scale the view to cover the new size and crop
    its centre (never stretched). A transforms.json with an empty 'frames' list gives no cameras
    when both are given, and raises otherwise (there is no size to check them against).
    Raises `DatasetError` (a `ValueError`) naming the file and field for malformed content, a
    PLY or other binary file included.
    """
    for name, v in (("width", width), ("height", height)):
        if v is not None:
            check_size(name, v)
    path = os.fspath(path)
    meta = read_json(path)
    if isinstance(meta, list):
        cameras = [_inria_camera(c, f"{path}: camera {i}") for i, c in enumerate(meta)]
    elif isinstance(meta, dict) and meta.get("frames") == []:
        if width is None or height is None:
            raise DatasetError(f"{path}: 'frames' is empty, so there is no image to read the "
                               "size from; pass width and height")
        cameras = []
    elif isinstance(meta, dict) and "frames" in meta:
        cameras = _transforms_cameras(meta, path)
    else:
        raise DatasetError(f"{path}: neither an INRIA cameras.json list nor a transforms.json")
    return [c.resized(width, height) for c in cameras]


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
