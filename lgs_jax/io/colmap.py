"""COLMAP sparse models (cameras, images, points3D), binary or text, read without pycolmap.

Why not pycolmap: a trainer needs three record files' poses, intrinsics and points, which this
module reads in pure Python with errors naming the file and record; pycolmap is a 38 MB compiled
wheel (4.2.1, Python 3.12) the GPU machine lacks. pycolmap 4.2.1 read the skull model exactly as
this reader does (a one-off check, tests/io/colmap_format.py).

Binary layout (little-endian; COLMAP's `reconstruction_io`, unchanged from 3.x to 4.x):
  cameras.bin   uint64 count; per camera: uint32 camera_id, int32 model_id, uint64 width,
                uint64 height, float64 params[n(model)]
  images.bin    uint64 count; per image: uint32 image_id, float64 qw qx qy qz, float64 tx ty tz,
                uint32 camera_id, name (bytes up to a NUL), uint64 n2d, n2d x (float64 x, float64 y,
                uint64 point3D_id)
  points3D.bin  uint64 count; per point: uint64 point3D_id, float64 x y z, uint8 r g b,
                float64 error, uint64 track_length, track_length x (uint32 image_id,
                uint32 point2D_idx)
Text layout: the same records, one per line ('#' comments), model by name; images.txt has two
lines per image, the second (the 2D points) possibly empty.

Poses: (qw, qx, qy, qz) and t give the world-to-camera transform x_cam = R(q)·x + t in OpenCV axes
(x right, y down, z forward). Pixel (i, j) has its centre at (j + 0.5, i + 0.5), as in lgs_jax.
The reader keeps what a trainer needs: cameras, image poses and names, point positions and colours
(2D keypoints and tracks are skipped).
"""

from __future__ import annotations

import dataclasses
import os
import struct

import numpy as np

from ..scene import rotation_problem
from .fields import number, positive
from .views import DISTORTION, DatasetError, Lens, Source, View

# model id: (name, number of parameters), as in COLMAP's sensor/models.h.
MODELS = {0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5),
          4: ("OPENCV", 8), 5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5),
          8: ("SIMPLE_RADIAL_FISHEYE", 4), 9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12),
          11: ("RAD_TAN_THIN_PRISM_FISHEYE", 16)}
NUM_PARAMS = {name: n for name, n in MODELS.values()}
# parameter names of the supported models (COLMAP's radial terms are OpenCV's k1, k2 on the same
# normalised coordinates; f is both focal lengths)
PARAMS = {"SIMPLE_PINHOLE": ("f", "cx", "cy"), "PINHOLE": ("fx", "fy", "cx", "cy"),
          "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"), "RADIAL": ("f", "cx", "cy", "k1", "k2"),
          "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")}
SUPPORTED = tuple(PARAMS)
# smallest record of each binary file (cameras: 3 parameters; images: empty name, no keypoints;
# points: empty track), to check a declared count against the file size before reading
MIN_RECORD = {"cameras": 4 + 4 + 8 + 8 + 3 * 8, "images": 4 + 7 * 8 + 4 + 1 + 8,
              "points": 8 + 3 * 8 + 3 + 8 + 8}


@dataclasses.dataclass(frozen=True)
class ColmapCamera:
    id: int
    model: str
    width: int
    height: int
    params: tuple[float, ...]


@dataclasses.dataclass(frozen=True)
class ColmapImage:
    id: int
    qvec: tuple[float, float, float, float]  # w, x, y, z (world to camera)
    tvec: tuple[float, float, float]
    camera_id: int
    name: str


@dataclasses.dataclass(frozen=True, eq=False)
class ColmapModel:
    """`cameras` / `images` by id; points as arrays: `point_ids` (M,) int64, `points` (M, 3)
    float64, `colors` (M, 3) uint8, `errors` (M,) float64 (mean reprojection error, pixels)."""

    cameras: dict[int, ColmapCamera]
    images: dict[int, ColmapImage]
    point_ids: np.ndarray
    points: np.ndarray
    colors: np.ndarray
    errors: np.ndarray


class _Bytes:
    """A cursor over a binary file; running past its end raises `DatasetError`."""

    def __init__(self, path: str):
        self.path, self.pos = path, 0
        with open(path, "rb") as f:
            self.buf = f.read()

    def take(self, fmt: str) -> tuple:
        size = struct.calcsize("<" + fmt)
        self.need(size)
        out = struct.unpack_from("<" + fmt, self.buf, self.pos)
        self.pos += size
        return out

    def need(self, size: int) -> None:
        if self.pos + size > len(self.buf):
            raise DatasetError(f"{self.path}: truncated (needs {size} bytes at offset {self.pos},"
                               f" has {len(self.buf) - self.pos})")

    def count(self, what: str) -> int:
        """The uint64 record count at the cursor, checked against the bytes left for records
        of at least `MIN_RECORD[what]` bytes each."""
        n = self.take("Q")[0]
        have = len(self.buf) - self.pos
        if n * MIN_RECORD[what] > have:
            raise DatasetError(f"{self.path}: declares {n} {what}, which need at least "
                               f"{n * MIN_RECORD[what]} bytes; the file has {have} after its count")
        return n

    def skip(self, size: int) -> None:
        self.need(size)
        self.pos += size

    def cstring(self) -> str:
        end = self.buf.find(b"\0", self.pos)
        if end < 0:
            raise DatasetError(f"{self.path}: truncated (unterminated image name)")
        out, self.pos = self.buf[self.pos:end].decode("utf-8"), end + 1
        return out

    def finish(self) -> None:
        if self.pos != len(self.buf):
            raise DatasetError(f"{self.path}: {len(self.buf) - self.pos} bytes after the last "
                               "record (not a COLMAP model file?)")


def _cameras_bin(path: str) -> dict[int, ColmapCamera]:
    f, out = _Bytes(path), {}
    for _ in range(f.count("cameras")):
        cid, model_id, w, h = f.take("IiQQ")
        if model_id not in MODELS:
            raise DatasetError(f"{path}: camera {cid} has unknown camera model id {model_id}")
        name, n = MODELS[model_id]
        out[cid] = ColmapCamera(cid, name, w, h, f.take(f"{n}d"))
    f.finish()
    return out


def _images_bin(path: str) -> dict[int, ColmapImage]:
    f, out = _Bytes(path), {}
    for _ in range(f.count("images")):
        iid, *pose, cid = f.take("I7dI")
        name = f.cstring()
        f.skip(24 * f.take("Q")[0])
        out[iid] = ColmapImage(iid, tuple(pose[:4]), tuple(pose[4:]), cid, name)
    f.finish()
    return out


def _points_bin(path: str):
    f = _Bytes(path)
    n = f.count("points")
    ids, xyz, rgb, err = np.zeros(n, np.int64), np.zeros((n, 3)), np.zeros((n, 3), np.uint8), \
        np.zeros(n)
    for i in range(n):
        ids[i], *xyz[i], r, g, b, err[i], track = f.take("Q3d3BdQ")
        rgb[i] = r, g, b
        f.skip(8 * track)
    f.finish()
    return ids, xyz, rgb, err


def _lines(path: str):
    """(line number, stripped line) of a text model file, comments and blank lines included."""
    with open(path, encoding="utf-8") as f:
        return [(i + 1, line.strip()) for i, line in enumerate(f)]


def _records(path: str):
    return [(i, line.split()) for i, line in _lines(path) if line and not line.startswith("#")]


def _parse(path: str, lineno: int, what: str, convert, items):
    try:
        return convert(items)
    except DatasetError:
        raise
    except (ValueError, IndexError, KeyError):
        raise DatasetError(f"{path}:{lineno}: cannot parse {what}: {' '.join(items)!r}") from None


def _cameras_txt(path: str) -> dict[int, ColmapCamera]:
    def camera(t):
        if len(t) > 1 and t[1] not in NUM_PARAMS:
            raise DatasetError(f"{path}: camera {t[0]} has unknown camera model {t[1]}")
        if len(t) != 4 + NUM_PARAMS[t[1]]:
            raise ValueError
        return ColmapCamera(int(t[0]), t[1], int(t[2]), int(t[3]), tuple(map(float, t[4:])))

    cams = [_parse(path, i, "a camera (ID MODEL WIDTH HEIGHT PARAMS...)", camera, t)
            for i, t in _records(path)]
    return {c.id: c for c in cams}


def _images_txt(path: str) -> dict[int, ColmapImage]:
    def image(t):
        if len(t) < 10:
            raise ValueError
        v = list(map(float, t[1:8]))
        return ColmapImage(int(t[0]), tuple(v[:4]), tuple(v[4:]), int(t[8]), " ".join(t[9:]))

    out, lines, k = {}, _lines(path), 0
    while k < len(lines):
        i, line = lines[k]
        k += 1
        if line and not line.startswith("#"):
            im = _parse(path, i, "an image (ID QW QX QY QZ TX TY TZ CAMERA_ID NAME)", image,
                        line.split())
            out[im.id] = im
            k += 1  # the 2D points line that follows every image line, even when empty
    return out


def _points_txt(path: str):
    def point(t):
        if len(t) < 8 or (len(t) - 8) % 2:
            raise ValueError
        return int(t[0]), tuple(map(float, t[1:4])), tuple(map(int, t[4:7])), float(t[7])

    rows = [_parse(path, i, "a point (ID X Y Z R G B ERROR TRACK...)", point, t)
            for i, t in _records(path)]
    ids, xyz, rgb, err = zip(*rows) if rows else ((), (), (), ())
    return (np.asarray(ids, np.int64), np.asarray(xyz, np.float64).reshape(-1, 3),
            np.asarray(rgb, np.uint8).reshape(-1, 3), np.asarray(err, np.float64))


def model_format(folder: str) -> str | None:
    """'.bin' or '.txt' if `folder` holds a COLMAP model (its cameras file), else None."""
    for ext in (".bin", ".txt"):
        if os.path.isfile(os.path.join(folder, "cameras" + ext)):
            return ext
    return None


def read_model(folder) -> ColmapModel:
    """The COLMAP model in `folder` (cameras, images, points3D; .bin preferred over .txt)."""
    folder = os.fspath(folder)
    ext = model_format(folder)
    if ext is None:
        raise DatasetError(f"{folder}: no COLMAP model (cameras.bin or cameras.txt)")
    readers = {".bin": (_cameras_bin, _images_bin, _points_bin),
               ".txt": (_cameras_txt, _images_txt, _points_txt)}[ext]
    parts = []
    for name, reader in zip(("cameras", "images", "points3D"), readers):
        path = os.path.join(folder, name + ext)
        try:
            parts.append(reader(path))
        except (OSError, UnicodeDecodeError) as e:
            raise DatasetError(f"{path}: cannot read ({e})") from None
    cameras, images, (ids, xyz, rgb, err) = parts
    return ColmapModel(cameras, images, ids, xyz, rgb, err)


def quat_to_rotation(q) -> np.ndarray:
    """Rotation matrix of a quaternion (w, x, y, z), normalised first."""
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def camera_lens(cam: ColmapCamera, where: str) -> Lens:
    """`Lens` of a camera of one of the `SUPPORTED` models; raises `DatasetError` naming `where`,
    the camera and the parameter for a focal length that is not finite and > 0, another
    parameter that is not finite, or an empty image size."""
    if cam.model not in PARAMS:
        raise DatasetError(f"{where}: camera {cam.id} has the unsupported camera model "
                           f"{cam.model} (supported: {', '.join(SUPPORTED)})")
    at = f"{where}: camera {cam.id} ({cam.model})"
    p = dict(zip(PARAMS[cam.model], cam.params))
    f = {k: positive(p, k, at) for k in ("f", "fx", "fy") if k in p}
    cx, cy = number(p, "cx", at), number(p, "cy", at)
    dist = tuple(number(p, k, at) if k in p else 0.0 for k in DISTORTION)
    if cam.width < 1 or cam.height < 1:
        raise DatasetError(f"{at}: image size {cam.width}x{cam.height} is empty")
    return Lens(f.get("fx", f.get("f")), f.get("fy", f.get("f")), cx, cy, int(cam.width),
                int(cam.height), dist)


def _pose(im: ColmapImage, where: str) -> np.ndarray:
    """World-to-camera matrix of an image; a quaternion that is zero or not finite, or a
    translation that is not finite, raises `DatasetError` naming `where` and the image."""
    at = f"{where}: image {im.name!r} (id {im.id})"
    norm = np.linalg.norm(im.qvec)
    rotation = quat_to_rotation(im.qvec) if np.isfinite(norm) and norm > 0 else None
    if rotation is None or rotation_problem(rotation):
        raise DatasetError(f"{at}: qvec {tuple(im.qvec)} is not a rotation (a zero or non-finite "
                           "quaternion)")
    if not np.all(np.isfinite(im.tvec)):
        raise DatasetError(f"{at}: tvec {tuple(im.tvec)} must be finite")
    view = np.eye(4)
    view[:3, :3], view[:3, 3] = rotation, im.tvec
    return view


def model_folder(root: str) -> str | None:
    """The model folder of a COLMAP dataset root: sparse/0 or sparse (None if neither)."""
    for sub in (("sparse", "0"), ("sparse",)):
        folder = os.path.join(root, *sub)
        if model_format(folder):
            return folder
    return None


def colmap_source(root: str) -> Source:
    """Views of a COLMAP dataset: the model in `model_folder(root)`, images in root/images.
    Cameras, poses and points are checked (`camera_lens`, `_pose`, finite points)."""
    folder = model_folder(root)
    model = read_model(folder)
    ext = model_format(folder)
    cams_file, images_file, points_file = (os.path.join(folder, n + ext)
                                           for n in ("cameras", "images", "points3D"))
    if not model.images:
        raise DatasetError(f"{images_file}: the model has no images (empty model)")
    lenses, views = {}, []
    for im in model.images.values():
        if im.camera_id not in model.cameras:
            raise DatasetError(f"{images_file}: image {im.name!r} uses camera {im.camera_id}, "
                               f"which {cams_file} does not define")
        if im.camera_id not in lenses:
            lenses[im.camera_id] = camera_lens(model.cameras[im.camera_id], cams_file)
        views.append(View(im.name.replace(os.sep, "/"), os.path.join(root, "images", im.name),
                          _pose(im, images_file), lenses[im.camera_id]))
    bad = ~np.all(np.isfinite(model.points), axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise DatasetError(f"{points_file}: point {model.point_ids[i]}: position "
                           f"{tuple(model.points[i].tolist())} is not finite")
    return Source(images_file, cams_file, views, model.points, model.colors)
