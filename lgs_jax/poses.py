"""Camera poses in OpenCV axes (x right, y down, z forward; `Camera.viewmat` world-to-camera):
a camera's centre and rotation, a camera moved to a pose, look-at rotations, and unit
quaternions (w, x, y, z) with spherical interpolation, for camera paths (lgs_jax.video) and
the viewer's cameras (lgs_jax.viewer)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .scene import Camera


def pose(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(camera centre, world-to-camera rotation) in float64."""
    view = np.asarray(cam.viewmat, np.float64)
    rot = view[:3, :3]
    return -rot.T @ view[:3, 3], rot


def posed(cam: Camera, centre, rot) -> Camera:
    """`cam`'s intrinsics and size at the pose (centre, world-to-camera rotation)."""
    view = np.eye(4)
    view[:3, :3] = rot
    view[:3, 3] = -rot @ centre
    return dataclasses.replace(cam, viewmat=view.astype(np.float32))


def axes_centre(cameras) -> np.ndarray:
    """The point nearest the cameras' optical axes in least squares, Σ (I − d dᵀ) (x − o) = 0
    over the axes (centre o, direction d). Raises `ValueError` for fewer than two cameras or
    axes (nearly) parallel, which meet nowhere."""
    if len(cameras) < 2:
        raise ValueError(f"cameras: their axes' nearest point needs at least 2 cameras, got "
                         f"{len(cameras)}")
    placed = [pose(c) for c in cameras]
    origins = np.stack([o for o, _ in placed])
    dirs = np.stack([r[2] for _, r in placed])
    projectors = np.eye(3) - dirs[:, :, None] * dirs[:, None, :]
    a, b = projectors.sum(0), np.einsum("nij,nj->i", projectors, origins)
    if np.linalg.cond(a) > 1e6:
        raise ValueError("cameras: their optical axes are (nearly) parallel; no centre to "
                         "orbit about")
    return np.linalg.solve(a, b)


def look_at(position, target, up) -> np.ndarray:
    """World-to-camera rotation (OpenCV axes: rows x right, y down, z forward) of a camera at
    `position` looking at `target`, image up as close to `up` as the view direction allows."""
    forward = np.asarray(target, np.float64) - np.asarray(position, np.float64)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, np.float64))
    norm = np.linalg.norm(right)
    if norm < 1e-9:
        raise ValueError("look_at: the view direction is parallel to up")
    right /= norm
    return np.stack([right, np.cross(forward, right), forward])


def quaternion(rot) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix."""
    w = math.sqrt(max(0.0, 1 + np.trace(rot))) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + rot[0, 0] - rot[1, 1] - rot[2, 2])) / 2,
                      rot[2, 1] - rot[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - rot[0, 0] + rot[1, 1] - rot[2, 2])) / 2,
                      rot[0, 2] - rot[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - rot[0, 0] - rot[1, 1] + rot[2, 2])) / 2,
                      rot[1, 0] - rot[0, 1])
    q = np.array([w, x, y, z])
    return q / np.linalg.norm(q)


def rotation(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def slerp(q0, q1, t: float) -> np.ndarray:
    """Spherical interpolation between unit quaternions along the shorter arc."""
    dot = float(q0 @ q1)
    if dot < 0:
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly equal: the chord, normalised
        q = q0 + t * (q1 - q0)
        return q / np.linalg.norm(q)
    angle = math.acos(dot)
    return (math.sin((1 - t) * angle) * q0 + math.sin(t * angle) * q1) / math.sin(angle)
