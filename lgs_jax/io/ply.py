"""INRIA 3DGS PLY files (binary little-endian), read and written by property name.

Layout (conventions.md, "INRIA PLY fields"): x y z [nx ny nz] f_dc_0..2 f_rest_0..3(K−1)−1
opacity scale_0..2 rot_0..3, with f_rest channel-major (all red coefficients of bases 1..K−1,
then green, then blue). Other properties are ignored; order does not matter.
"""

from __future__ import annotations

import os

import numpy as np

from ..scene import SH_BASES, Gaussians

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_NAMES = {np.dtype("f4"): "float", np.dtype("f8"): "double"}


class PlyError(ValueError):
    """A PLY file that is not a binary little-endian INRIA Gaussian file; the message says why."""


def _header_lines(f, path):
    """Yield (line number, words) of the header lines up to `end_header` (excluded)."""
    number = 1
    while True:
        line = f.readline()
        number += 1
        if not line:
            raise PlyError(f"{path}: truncated header (no end_header)")
        if not line.endswith(b"\n"):
            raise PlyError(f"{path}: header cut off in line {number} ({line[:40]!r}; "
                           "no end_header)")
        words = line.decode("ascii", "replace").split()
        if words and words[0] == "end_header":
            return
        if words and words[0] not in ("comment", "obj_info"):
            yield number, words


def _vertex_count(words, path, number) -> int:
    """The count of an `element vertex COUNT` line: a non-negative integer."""
    if len(words) != 3 or not words[2].isdigit():
        raise PlyError(f"{path}: line {number}: {' '.join(words)!r}: the vertex count must be a "
                       "non-negative integer")
    return int(words[2])


def _property(words, path, number):
    """(name, numpy type) of a `property TYPE NAME` line of the vertex element."""
    if len(words) > 1 and words[1] == "list":
        raise PlyError(f"{path}: list property {words[-1]!r} in vertex is not supported")
    if len(words) != 3:
        raise PlyError(f"{path}: line {number}: {' '.join(words)!r} is not 'property TYPE NAME'")
    if words[1] not in _PLY_TYPES:
        raise PlyError(f"{path}: line {number}: unknown property type {words[1]!r}")
    return words[2], "<" + _PLY_TYPES[words[1]]


def _read_header(f, path):
    """Parse the header: (vertex count, numpy dtype of one vertex record)."""
    first = f.readline()
    if first.rstrip(b"\r\n") != b"ply":
        raise PlyError(f"{path}: not a PLY file (first line {first[:20]!r})")
    fmt, count, props, in_vertex = None, None, [], False
    for number, words in _header_lines(f, path):
        if words[0] == "format":
            fmt = words[1] if len(words) > 1 else ""
        elif words[0] == "element":
            in_vertex = len(words) > 1 and words[1] == "vertex"
            if in_vertex:
                count = _vertex_count(words, path, number)
            elif count is not None:
                name = words[1] if len(words) > 1 else ""
                raise PlyError(f"{path}: element {name!r} after vertex is not supported")
        elif words[0] == "property" and in_vertex:
            props.append(_property(words, path, number))
    if fmt != "binary_little_endian":
        raise PlyError(f"{path}: format {fmt!r} is not supported; need binary_little_endian")
    if count is None:
        raise PlyError(f"{path}: no vertex element")
    return count, np.dtype(props)


def load_ply(path) -> Gaussians:
    """Read an INRIA PLY into `Gaussians` (numpy arrays in the file's float precision)."""
    path = os.fspath(path)
    with open(path, "rb") as f:
        count, dtype = _read_header(f, path)
        data = f.read()
    if len(data) < count * dtype.itemsize:
        raise PlyError(f"{path}: truncated: {count} vertices need {count * dtype.itemsize} bytes, "
                       f"file has {len(data)}")
    v = np.frombuffer(data, dtype=dtype, count=count)
    names = set(dtype.names)
    required = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
                "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    missing = [n for n in required if n not in names]
    if missing:
        raise PlyError(f"{path}: missing required properties {missing}")
    n_rest = sum(1 for n in names if n.startswith("f_rest_"))
    if n_rest % 3 or n_rest // 3 + 1 not in SH_BASES:
        raise PlyError(f"{path}: {n_rest} f_rest properties is not 3·(K−1) for SH degree 0..3")
    missing = [f"f_rest_{i}" for i in range(n_rest) if f"f_rest_{i}" not in names]
    if missing:
        raise PlyError(f"{path}: missing properties {missing}")
    ftype = np.result_type(*[dtype[n] for n in required])
    col = lambda *ns: np.stack([v[n] for n in ns], axis=-1).astype(ftype)
    k = n_rest // 3 + 1
    rest = np.stack([v[f"f_rest_{i}"] for i in range(n_rest)] or [np.zeros((count, 0))], -1)
    rest = rest.astype(ftype).reshape(count, 3, k - 1)
    sh = np.concatenate([col("f_dc_0", "f_dc_1", "f_dc_2")[:, None, :],
                         rest.transpose(0, 2, 1)], axis=1)
    return Gaussians(means=col("x", "y", "z"), quats=col("rot_0", "rot_1", "rot_2", "rot_3"),
                     log_scales=col("scale_0", "scale_1", "scale_2"),
                     logit_opacities=v["opacity"].astype(ftype), sh=sh)


def save_ply(path, gaussians: Gaussians) -> None:
    """Write `gaussians` as an INRIA PLY in its own float precision (load_ply reads it back
    bit-identically); normals are written as zeros."""
    g = {k: np.asarray(getattr(gaussians, k)) for k in
         ("means", "quats", "log_scales", "logit_opacities", "sh")}
    ftype = np.result_type(*g.values())
    if ftype not in _NAMES:
        raise ValueError(f"gaussians: dtype {ftype} cannot be written; use float32 or float64")
    n, k = g["sh"].shape[:2]
    cols = {"x": g["means"][:, 0], "y": g["means"][:, 1], "z": g["means"][:, 2]}
    cols.update({f"n{a}": np.zeros(n, ftype) for a in "xyz"})
    cols.update({f"f_dc_{c}": g["sh"][:, 0, c] for c in range(3)})
    rest = g["sh"][:, 1:, :].transpose(0, 2, 1).reshape(n, 3 * (k - 1))
    cols.update({f"f_rest_{i}": rest[:, i] for i in range(3 * (k - 1))})
    cols["opacity"] = g["logit_opacities"]
    cols.update({f"scale_{i}": g["log_scales"][:, i] for i in range(3)})
    cols.update({f"rot_{i}": g["quats"][:, i] for i in range(4)})
    out = np.empty(n, dtype=[(name, "<" + ftype.str[1:]) for name in cols])
    for name, values in cols.items():
        out[name] = values
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {n}"]
    header += [f"property {_NAMES[ftype]} {name}" for name in cols] + ["end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(out.tobytes())
