"""Videos of a scene along a camera path: an orbit fitted to a capture's cameras, or the
capture's own cameras in order with the poses between them interpolated; every frame one
`lgs_jax.render` call (one compile: the frames share the image size), written as an H.264 MP4
through imageio-ffmpeg.

    cams = orbit_path(lgs_jax.load_cameras("cameras.json"), frames=120)
    write_video("orbit.mp4", render_frames(scene, cams), fps=30)

The orbit (`orbit_path`): the centre is the point nearest to every camera's optical axis (least
squares: Σ_i (I − d_i d_iᵀ)(c − o_i) = 0 for camera centres o_i and viewing directions d_i),
the axis is the cameras' mean "up" (−y of OpenCV camera axes), and the path is the circle about
that axis through the cameras' mean height and mean distance from it, starting at the first
camera, every frame looking at the centre. Intrinsics and image size are the first camera's.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from . import poses
from .files import written
from .scene import Camera


def _check_frames(frames) -> None:
    if not isinstance(frames, (int, np.integer)) or isinstance(frames, bool) or frames < 1:
        raise ValueError(f"frames: expected an int >= 1, got {frames!r}")


def orbit_path(cameras, frames: int, turns: float = 1.0) -> list[Camera]:
    """`frames` cameras on the orbit fitted to `cameras` (module docstring), `turns` times
    around from the first camera off the axis (the last frame one step short of the start,
    so the video loops). Raises
    `ValueError` for fewer than two cameras, optical axes too close to parallel to meet, or
    cameras on the orbit's axis."""
    _check_frames(frames)
    if len(cameras) < 2:
        raise ValueError(f"cameras: an orbit needs at least 2 cameras, got {len(cameras)}")
    centre = poses.axes_centre(cameras)
    placed = [poses.pose(c) for c in cameras]
    origins = np.stack([o for o, _ in placed])
    up = -np.mean([r[1] for _, r in placed], 0)
    up /= np.linalg.norm(up)
    rel = origins - centre
    height = float(np.mean(rel @ up))
    flat = rel - np.outer(rel @ up, up)
    off_axis = np.linalg.norm(flat, axis=1)
    radius = float(np.mean(off_axis))
    if radius <= 1e-9 * (1 + np.abs(origins).max()):
        raise ValueError("cameras: they lie on the orbit's axis")
    first = int(np.argmax(off_axis > 1e-6 * radius))  # the first camera off the axis
    e1 = flat[first] / off_axis[first]
    e2 = np.cross(up, e1)
    out = []
    for k in range(frames):
        theta = 2 * math.pi * turns * k / frames
        position = centre + height * up + radius * (math.cos(theta) * e1 + math.sin(theta) * e2)
        out.append(poses.posed(cameras[0], position, poses.look_at(position, centre, up)))
    return out


def camera_path(cameras, frames: int) -> list[Camera]:
    """`frames` cameras through `cameras` in order, the first to the last: centres linear and
    rotations spherically interpolated between neighbours, at equal steps of the path's
    parameter (one unit per pair of neighbours). Intrinsics and size are the first camera's."""
    _check_frames(frames)
    if not cameras:
        raise ValueError("cameras: none given")
    keys = [(o, poses.quaternion(r)) for o, r in map(poses.pose, cameras)]
    if len(keys) == 1 or frames == 1:
        o, q = keys[0]
        return [poses.posed(cameras[0], o, poses.rotation(q))] * frames
    out = []
    for k in range(frames):
        s = k * (len(keys) - 1) / (frames - 1)
        i = min(int(s), len(keys) - 2)
        t = s - i
        (o0, q0), (o1, q1) = keys[i], keys[i + 1]
        rot = poses.rotation(poses.slerp(q0, q1, t))
        out.append(poses.posed(cameras[0], (1 - t) * o0 + t * o1, rot))
    return out


def render_output(scene, cam, capacity: int | None = None, headroom: float = 1.0,
                  **render_kwargs):
    """(RenderOutput, capacity): `lgs_jax.render(scene, cam, capacity=capacity,
    **render_kwargs)` and the pair buffer it used. Pass that capacity to the next call so that
    views share compiled programs: it is sized anew (one recompile) only when a view needs more
    pairs, to `pair_capacity(pairs, headroom)` (a headroom above 1 leaves room for a scene that
    grows, as in training)."""
    from .render import CapacityError, pair_capacity, render

    try:
        out = render(scene, cam, capacity=capacity, **render_kwargs)
    except CapacityError as e:
        if capacity is None:  # more pairs than int32 indexes: nothing to grow into
            raise
        out = render(scene, cam, capacity=pair_capacity(e.required, headroom), **render_kwargs)
    return out, int(out.stats.capacity)


def to_uint8(image) -> np.ndarray:
    """An image in [0, 1] (clipped) as uint8, rounded."""
    return np.round(np.clip(np.asarray(image), 0.0, 1.0) * 255).astype(np.uint8)


OUTPUTS = ("image", "depth", "alpha")
"""What a frame shows (`frame_pixels`)."""


def _expected_depth(out):
    """(Σ z·α·T / alpha, the mask alpha >= 0.05 where that is shown) of a render."""
    alpha = np.asarray(out.alpha, np.float64)
    seen = alpha >= 0.05
    return np.asarray(out.depth, np.float64) / np.where(seen, alpha, 1.0), seen


def depth_range(out) -> tuple[float, float]:
    """The 1st and 99th percentiles of a render's expected depth Σ z·α·T / alpha over its
    pixels with alpha >= 0.05 ((0, 1) where there are none): `frame_pixels`' colour range."""
    return _percentiles(*_expected_depth(out))


def _percentiles(depth, seen) -> tuple[float, float]:
    if not seen.any():
        return 0.0, 1.0
    lo, hi = np.percentile(depth[seen], [1, 99])
    return float(lo), float(hi)


def frame_pixels(out, output: str, span=None) -> np.ndarray:
    """A `RenderOutput` as (H, W, 3) uint8: "image" its colour; "alpha" 1 − T in grey;
    "depth" the expected depth Σ z·α·T / alpha through matplotlib's turbo colour map, near
    (blue) to far (red) over `span` = (lo, hi), by default this render's `depth_range`
    (black where alpha < 0.05)."""
    if output == "image":
        return to_uint8(out.image)
    if output == "alpha":
        return np.repeat(to_uint8(out.alpha)[..., None], 3, -1)
    if output != "depth":
        raise ValueError(f"output: expected one of {OUTPUTS}, got {output!r}")
    import matplotlib

    depth, seen = _expected_depth(out)
    lo, hi = span or _percentiles(depth, seen)
    t = np.clip((depth - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    return to_uint8(matplotlib.colormaps["turbo"](t)[..., :3] * seen[..., None])


def render_frames(scene, cameras, output: str = "image", **render_kwargs):
    """Each camera's frame (`frame_pixels` of `output`; the depth's colour range the first
    frame's `depth_range`, so that colours mean the same depth in every frame), the pair
    buffer carried from frame to frame; a generator."""
    capacity, span = None, None
    for cam in cameras:
        out, capacity = render_output(scene, cam, capacity, **render_kwargs)
        if output == "depth" and span is None:
            span = depth_range(out)
        yield frame_pixels(out, output, span)


def write_video(path: str, frames, fps: float = 30.0, quality: float = 8.0) -> int:
    """Write uint8 (height, width, 3) `frames` (an iterable) to `path` as H.264 MP4 (yuv420p,
    imageio-ffmpeg's bundled ffmpeg; `quality` 0–10, its scale); returns the frame count.
    The video is written under a temporary name beside `path` and renamed at the end
    (`lgs_jax.files.written`): an error or an interruption leaves no shorter video at `path`.
    Raises `ValueError` for frames of another shape or dtype, or of odd width or height
    (H.264's 4:2:0 chroma needs even sizes; ffmpeg would otherwise rescale them)."""
    with written(path) as tmp:
        return _write_frames(tmp, frames, fps, quality)


def _write_frames(path: str, frames, fps: float, quality: float) -> int:
    import imageio_ffmpeg

    writer, shape, count = None, None, 0
    try:
        for frame in frames:
            frame = np.asarray(frame)
            if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
                raise ValueError(f"frames: expected (height, width, 3) uint8, got "
                                 f"{frame.shape} {frame.dtype}")
            if writer is None:
                shape = frame.shape
                h, w = shape[:2]
                if h % 2 or w % 2:
                    raise ValueError(f"frames: H.264 needs an even width and height, got "
                                     f"{w}x{h}")
                writer = imageio_ffmpeg.write_frames(path, (w, h), fps=fps, quality=quality,
                                                     macro_block_size=1)
                with warnings.catch_warnings():  # ffmpeg is exec'd at once: JAX's warning
                    warnings.filterwarnings("ignore", "os.fork", RuntimeWarning)  # is moot
                    writer.send(None)  # start ffmpeg
            elif frame.shape != shape:
                raise ValueError(f"frames: frame {count} is {frame.shape}, the first {shape}")
            writer.send(np.ascontiguousarray(frame))
            count += 1
    finally:
        if writer is not None:
            writer.close()
    return count
