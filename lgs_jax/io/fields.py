"""JSON camera files (cameras.json, transforms.json) and COLMAP camera parameters: reading the
file and checking each field as it is read.

Every check raises `DatasetError` (a `ValueError`) naming `where` (the file, and the camera, frame
or image within it), the field and the value it got.
"""

from __future__ import annotations

import json
import math
import numbers

import numpy as np

from .views import DatasetError


def read_json(path: str):
    """The parsed JSON of the camera file `path`. A PLY or other binary file, text that is not
    UTF-8 and malformed JSON each raise `DatasetError` saying so (malformed JSON with its line);
    `OSError` for a file that cannot be opened."""
    with open(path, "rb") as f:
        if f.read(4) in (b"ply\n", b"ply\r"):
            raise DatasetError(f"{path}: is a PLY file, not a cameras file (cameras.json or "
                               "transforms.json)")
        f.seek(0)
        data = f.read()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise DatasetError(f"{path}: not a cameras file: not UTF-8 text (byte {e.start} is "
                           f"{data[e.start:e.start + 1]!r})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise DatasetError(f"{path}: not valid JSON: {e}") from None


def number(c: dict, key: str, where: str) -> float:
    """`c[key]` as a finite float (a JSON number, not a string or boolean)."""
    if key not in c:
        raise DatasetError(f"{where}: missing {key!r}")
    v = c[key]
    if not isinstance(v, numbers.Real) or isinstance(v, bool) or not math.isfinite(v):
        raise DatasetError(f"{where}: {key} must be a finite number, got {v!r}")
    return float(v)


def positive(c: dict, key: str, where: str) -> float:
    """`c[key]` as a finite float > 0 (a focal length in pixels)."""
    v = c.get(key)
    if key in c and isinstance(v, numbers.Real) and not isinstance(v, bool) \
            and math.isfinite(v) and v > 0:
        return float(v)
    if key not in c:
        raise DatasetError(f"{where}: missing {key!r}")
    raise DatasetError(f"{where}: {key} must be a finite number > 0, got {v!r}")


def field_of_view(c: dict, key: str, where: str) -> float:
    """`c[key]` as a field of view in radians, 0 < a < π."""
    v = c.get(key)
    if isinstance(v, numbers.Real) and not isinstance(v, bool) and 0 < v < math.pi:
        return float(v)
    raise DatasetError(f"{where}: {key} must be a field of view in radians, 0 < a < π, got "
                       f"{v!r}")


def pixels(c: dict, key: str, where: str) -> int:
    """`c[key]` as a positive whole number of pixels (1280 or 1280.0, not 1280.7 or "1280")."""
    v = number(c, key, where)
    if v <= 0 or not v.is_integer():
        raise DatasetError(f"{where}: {key} must be a positive whole number of pixels, got "
                           f"{c[key]!r}")
    return int(v)


def matrix(c: dict, key: str, shape: tuple, where: str) -> np.ndarray:
    """`c[key]` as a float64 array of `shape` with finite entries."""
    if key not in c:
        raise DatasetError(f"{where}: missing {key!r}")
    try:
        m = np.asarray(c[key], np.float64)
    except (TypeError, ValueError):
        m = None
    if m is None or m.shape != shape or not np.all(np.isfinite(m)):
        raise DatasetError(f"{where}: {key} must be {'x'.join(map(str, shape))} finite numbers, "
                           f"got {c[key]!r}")
    return m
