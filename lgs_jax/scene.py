"""Scene and camera pytrees (the rendering contract's parameters, `docs/conventions.md`).

Both are registered dataclass pytrees: every array field is a leaf, so scenes and cameras pass
through `jit`, `vmap` and `grad`. `Camera.width` / `Camera.height` are static (pytree metadata):
a new camera pose or intrinsics never recompiles, a new image size does.

Validation lives in `validate_gaussians` / `validate_camera` / `validate_background` (called by
`render`), not in `__post_init__`: JAX rebuilds pytrees with placeholder leaves (vmap axis specs,
tracers), which a constructor must accept unchanged.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

SH_BASES = (1, 4, 9, 16)  # K = (degree + 1)^2 for degrees 0..3


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class Gaussians:
    """3D Gaussians in stored (pre-activation) form, as in INRIA PLY files.

    Attributes:
      means: (N, 3) world-space centres.
      quats: (N, 4) rotations as w, x, y, z; need not be unit length (normalised on use).
      log_scales: (N, 3) per-axis log standard deviations; scale = exp(log_scales).
      logit_opacities: (N,) opacity = sigmoid(logit); +inf is a valid, fully opaque Gaussian.
      sh: (N, K, 3) spherical-harmonic colour coefficients, K = (degree + 1)^2 in {1, 4, 9, 16}.
    """

    means: Any
    quats: Any
    log_scales: Any
    logit_opacities: Any
    sh: Any

    @property
    def num(self) -> int:
        return int(np.shape(self.means)[0])

    @property
    def sh_degree(self) -> int:
        return SH_BASES.index(int(np.shape(self.sh)[1]))

    @property
    def dtype(self):
        return jnp.result_type(self.means)


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class Camera:
    """A pinhole camera with OpenCV axes (x right, y down, z forward).

    Attributes:
      viewmat: (4, 4) world-to-camera matrix.
      fx, fy, cx, cy: intrinsics in pixels; pixel (i, j) has its centre at (j + 0.5, i + 0.5).
      width, height: image size in pixels (static: part of the pytree structure).
      near, far: a Gaussian is rendered only if near < camera-space z < far.
    """

    viewmat: Any
    fx: Any
    fy: Any
    cx: Any
    cy: Any
    width: int = dataclasses.field(metadata=dict(static=True))
    height: int = dataclasses.field(metadata=dict(static=True))
    near: Any = 0.01
    far: Any = 1e10

    def scaled(self, width: int, height: int) -> "Camera":
        """The same view at another resolution (intrinsics scaled per axis: a new aspect ratio
        stretches the image; `resized` keeps it)."""
        sx, sy = width / self.width, height / self.height
        return dataclasses.replace(self, fx=self.fx * sx, fy=self.fy * sy, cx=self.cx * sx,
                                   cy=self.cy * sy, width=int(width), height=int(height))

    def resized(self, width: int | None = None, height: int | None = None) -> "Camera":
        """The same view at another image size, never stretched.

        One of `width`/`height` given: the other follows this camera's aspect ratio (rounded,
        at least 1). Both given with another aspect ratio: the view is scaled uniformly until it
        covers width x height, then centre-cropped (the field of view narrows along one axis).
        Neither: this camera. Raises `ValueError` for a size that is not a positive int.
        """
        for name, v in (("width", width), ("height", height)):
            if v is not None:
                check_size(name, v)
        if width is None and height is None:
            return self
        if width is None:
            width = max(1, round(self.width * height / self.height))
        elif height is None:
            height = max(1, round(self.height * width / self.width))
        s = max(width / self.width, height / self.height)
        return dataclasses.replace(
            self, fx=self.fx * s, fy=self.fy * s, cx=self.cx * s - (self.width * s - width) / 2,
            cy=self.cy * s - (self.height * s - height) / 2, width=int(width), height=int(height))

    def cropped(self, x0: int, y0: int, width: int, height: int) -> "Camera":
        """The window [x0, x0 + width) x [y0, y0 + height) of this camera's image, as a camera
        (principal point shifted; pixel (0, 0) of the crop is pixel (x0, y0) here)."""
        return dataclasses.replace(self, cx=self.cx - x0, cy=self.cy - y0, width=width,
                                   height=height)


def stack_cameras(cameras: list[Camera]) -> Camera:
    """Stack same-size cameras into one batched `Camera` for `jax.vmap`."""
    sizes = {(c.width, c.height) for c in cameras}
    if len(sizes) != 1:
        raise ValueError(f"cameras: stacking needs one image size, got {sorted(sizes)}")
    return jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *cameras)


ORTHO_TOL = 1e-4  # |R·Rᵀ − I| and last-row tolerance of a viewmat (float32 files round ~1e-7)


def check_size(name: str, v) -> None:
    """Raise `ValueError` naming `name` unless `v` is a positive int (an image side in pixels)."""
    if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v <= 0:
        raise ValueError(f"{name}: expected a positive int, got {v!r}")


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _check_array(name: str, x) -> None:
    """Raise unless `x` is a numpy or JAX array (a tracer included): Python lists and scalars
    would be converted with JAX's default dtype, silently changing the precision."""
    if not isinstance(x, (np.ndarray, jax.Array)):
        raise ValueError(f"{name}: expected a numpy or JAX array, got {type(x).__name__} "
                         f"(convert it, e.g. np.asarray(x, np.float32))")


def validate_gaussians(g: Gaussians) -> None:
    """Raise `ValueError` naming the field if types, shapes or dtypes break the contract.

    Fields must be arrays (not lists) of one float dtype, float32 or float64; float64 needs
    `jax_enable_x64` (without it JAX would silently compute in float32)."""
    if not isinstance(g, Gaussians):
        raise ValueError(f"gaussians: expected lgs_jax.Gaussians, got {type(g).__name__}")
    for f in dataclasses.fields(g):
        _check_array(f"gaussians.{f.name}", getattr(g, f.name))
    shapes = {f.name: np.shape(getattr(g, f.name)) for f in dataclasses.fields(g)}
    n = shapes["means"][0] if len(shapes["means"]) == 2 else None
    want = {"means": (n, 3), "quats": (n, 4), "log_scales": (n, 3), "logit_opacities": (n,)}
    for name, shape in want.items():
        if n is None or shapes[name] != shape:
            raise ValueError(f"gaussians.{name}: expected shape {('N',) + shape[1:]} with N "
                             f"shared by all fields, got {shapes[name]}")
    sh = shapes["sh"]
    if len(sh) != 3 or sh[0] != n or sh[2] != 3:
        raise ValueError(f"gaussians.sh: expected shape (N, K, 3), got {sh}")
    if sh[1] not in SH_BASES:
        raise ValueError(f"gaussians.sh: K = {sh[1]} is not (degree+1)^2 for degree 0..3")
    _check_dtypes({f.name: np.dtype(getattr(g, f.name).dtype) for f in dataclasses.fields(g)})


def _check_dtypes(dtypes: dict) -> None:
    """One floating dtype for all Gaussian fields, float32 or float64 (the latter with x64)."""
    for name, dt in dtypes.items():
        if not np.issubdtype(dt, np.floating):
            raise ValueError(f"gaussians.{name}: expected a floating dtype, got {dt}")
        if dt != dtypes["means"]:
            raise ValueError(f"gaussians.{name}: dtype {dt} differs from means' {dtypes['means']}"
                             " (all fields must share one precision)")
    if dtypes["means"] not in (np.float32, np.float64):
        raise ValueError(f"gaussians.means: dtype {dtypes['means']} unsupported; use float32 "
                         "or float64 (render low precision by casting up)")
    if dtypes["means"] == np.float64 and not jax.config.jax_enable_x64:
        raise ValueError("gaussians.means: float64 needs jax.config.update('jax_enable_x64', "
                         "True) (without it JAX computes in float32); or cast to float32")


def validate_camera(cam: Camera) -> None:
    """Raise `ValueError` naming the argument for bad camera types or shapes, and (when the
    values are concrete, not traced) bad values: non-finite or non-positive intrinsics, near/far
    out of order, a viewmat whose last row is not (0, 0, 0, 1) or whose rotation is not a proper
    rotation (orthonormal to `ORTHO_TOL`, determinant +1)."""
    if not isinstance(cam, Camera):
        raise ValueError(f"camera: expected lgs_jax.Camera, got {type(cam).__name__}")
    for name in ("width", "height"):
        check_size(f"camera.{name}", getattr(cam, name))
    if math.ceil(cam.width / 16) * math.ceil(cam.height / 16) >= 2**24:
        raise ValueError(f"camera: {cam.width}x{cam.height} has too many 16x16 tiles")
    _check_array("camera.viewmat", cam.viewmat)
    if np.shape(cam.viewmat) != (4, 4):
        raise ValueError(f"camera.viewmat: expected shape (4, 4), got {np.shape(cam.viewmat)}")
    for name in ("fx", "fy", "cx", "cy", "near", "far"):
        if np.shape(getattr(cam, name)) != ():
            raise ValueError(f"camera.{name}: expected a scalar, got shape "
                             f"{np.shape(getattr(cam, name))} (vmap to batch cameras)")
    leaves = {n: getattr(cam, n) for n in ("viewmat", "fx", "fy", "cx", "cy", "near", "far")}
    if all(_is_concrete(v) for v in leaves.values()):
        _check_camera_values({n: np.asarray(v, dtype=np.float64) for n, v in leaves.items()})


def _check_camera_values(vals: dict) -> None:
    """The value checks of `validate_camera` on concrete float64 copies of the leaves."""
    for name in ("viewmat", "fx", "fy", "cx", "cy", "near"):
        if not np.all(np.isfinite(vals[name])):
            raise ValueError(f"camera.{name}: must be finite, got {vals[name]}")
    for name in ("fx", "fy"):
        if vals[name] <= 0:
            raise ValueError(f"camera.{name}: must be > 0, got {vals[name]}")
    if not vals["near"] > 0:
        raise ValueError(f"camera.near: must be > 0, got {vals['near']}")
    if np.isnan(vals["far"]) or not vals["near"] < vals["far"]:
        raise ValueError(f"camera.near/far: need 0 < near < far, got {vals['near']}, {vals['far']}")
    view = vals["viewmat"]
    if np.max(np.abs(view[3] - [0, 0, 0, 1])) > ORTHO_TOL:
        raise ValueError(f"camera.viewmat: last row must be (0, 0, 0, 1), got {view[3]}")
    problem = rotation_problem(view[:3, :3])
    if problem:
        raise ValueError(f"camera.viewmat: its 3x3 rotation {problem}")


def rotation_problem(r) -> str | None:
    """Why the 3x3 matrix `r` is not a rotation (orthonormal to `ORTHO_TOL`, determinant +1),
    or None if it is one."""
    err = float(np.max(np.abs(r @ r.T - np.eye(3))))
    if err > ORTHO_TOL:
        return f"is not orthonormal (max |R·Rᵀ − I| = {err:.3g} > {ORTHO_TOL})"
    if np.linalg.det(r) < 0:
        return "is a reflection (determinant −1), not a rotation"
    return None


def validate_background(background, channels: int = 3) -> None:
    """Raise `ValueError` unless `background` is a (channels,) colour (array or sequence) and,
    when concrete, finite (a NaN or inf background would reach every pixel of the image)."""
    if np.shape(background) != (channels,):
        raise ValueError(f"background: expected shape ({channels},), got "
                         f"{np.shape(background)}")
    if all(_is_concrete(x) for x in jax.tree.leaves(background)):
        values = np.asarray(background, dtype=np.float64)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"background: must be finite, got {values}")
