"""INRIA 3DGS PLY files, read and written by property name.

Layout (docs/conventions.md, "INRIA PLY fields"): x y z [nx ny nz] f_dc_0..2 f_rest_0..3(K−1)−1
opacity scale_0..2 rot_0..3, with f_rest channel-major (all red coefficients of bases 1..K−1,
then green, then blue). Other properties are ignored; order does not matter.

`load_ply` reads binary little- and big-endian and ascii files. Elements other than `vertex` are
skipped: those before it by their declared sizes (in binary files, only elements without list
properties can be sized; a list property there is refused), those after it are never read.
Declared counts are checked against the file size before anything is allocated. `save_ply`
writes binary little-endian.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from ..scene import SH_BASES, Gaussians

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_NAMES = {np.dtype("f4"): "float", np.dtype("f8"): "double"}
_BYTE_ORDER = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "="}
_REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
             "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")


class PlyError(ValueError):
    """A PLY file that is not an INRIA Gaussian file this reader can read; the message says why."""


@dataclasses.dataclass
class _Element:
    """One `element NAME COUNT` of the header: `props` holds (name, type word, header line) of
    each property, `lists` the names of its list properties (type word None in `props`)."""

    name: str
    count: int
    props: list = dataclasses.field(default_factory=list)
    lists: list = dataclasses.field(default_factory=list)

    def types(self, path: str) -> list[tuple[str, str]]:
        """(name, numpy type) of each scalar property; raise for unknown types and names
        declared twice (checked only for the elements that are read or skipped by size)."""
        out = []
        for name, word, number in self.props:
            if word is not None and word not in _PLY_TYPES:
                raise PlyError(f"{path}: line {number}: unknown property type {word!r}")
            if any(name == other for other, _ in out):
                raise PlyError(f"{path}: line {number}: element {self.name!r} declares property "
                               f"{name!r} twice")
            out.append((name, _PLY_TYPES.get(word)))
        return out


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


def _element(words, path, number) -> _Element:
    """An `element NAME COUNT` line; COUNT must be a non-negative integer."""
    name = words[1] if len(words) > 1 else ""
    if len(words) != 3 or not words[2].isdigit():
        what = "the vertex count" if name == "vertex" else f"the count of element {name!r}"
        raise PlyError(f"{path}: line {number}: {' '.join(words)!r}: {what} must be a "
                       "non-negative integer")
    return _Element(name, int(words[2]))


def _add_property(element, words, path, number) -> None:
    """Add a `property TYPE NAME` or `property list COUNT_TYPE ITEM_TYPE NAME` line."""
    if element is None:
        raise PlyError(f"{path}: line {number}: property before any element")
    if len(words) > 1 and words[1] == "list":
        if element.name == "vertex":
            raise PlyError(f"{path}: list property {words[-1]!r} in vertex is not supported")
        if len(words) != 5:
            raise PlyError(f"{path}: line {number}: {' '.join(words)!r} is not 'property list "
                           "COUNT_TYPE ITEM_TYPE NAME'")
        element.lists.append(words[4])
        element.props.append((words[4], None, number))
    elif len(words) != 3:
        raise PlyError(f"{path}: line {number}: {' '.join(words)!r} is not 'property TYPE NAME'")
    else:
        element.props.append((words[2], words[1], number))


def _read_header(f, path):
    """Parse the header: (format, the elements before vertex, the vertex element)."""
    first = f.readline()
    if first.rstrip(b"\r\n") != b"ply":
        raise PlyError(f"{path}: not a PLY file (first line {first[:20]!r})")
    fmt, elements = None, []
    for number, words in _header_lines(f, path):
        if words[0] == "format":
            fmt = words[1] if len(words) > 1 else ""
        elif words[0] == "element":
            elements.append(_element(words, path, number))
        elif words[0] == "property":
            _add_property(elements[-1] if elements else None, words, path, number)
    if fmt not in _BYTE_ORDER:
        raise PlyError(f"{path}: format {fmt!r} is not supported; need ascii, "
                       "binary_little_endian or binary_big_endian")
    names = [e.name for e in elements]
    if "vertex" not in names:
        raise PlyError(f"{path}: no vertex element")
    if names.count("vertex") > 1:
        raise PlyError(f"{path}: more than one vertex element")
    k = names.index("vertex")
    return fmt, elements[:k], elements[k]


def _binary_vertices(f, path, fmt, before, vertex):
    """The vertex records of a binary file, as a numpy structured array."""
    order = _BYTE_ORDER[fmt]
    for e in before:
        if e.lists:
            raise PlyError(f"{path}: element {e.name!r} before vertex has the list property "
                           f"{e.lists[0]!r}, so its size in a binary file is unknown (only "
                           "elements after vertex may have list properties)")
    sizes = [e.count * np.dtype([(n, order + t) for n, t in e.types(path)]).itemsize
             for e in before]
    dtype = np.dtype([(n, order + t) for n, t in vertex.types(path)])
    need = sum(sizes) + vertex.count * dtype.itemsize
    have = os.fstat(f.fileno()).st_size - f.tell()
    if need > have:
        prior = "".join(f"element {e.name!r} ({e.count} records) and " for e in before)
        raise PlyError(f"{path}: truncated: {prior}{vertex.count} vertices need {need} bytes, "
                       f"the file has {have} after its header")
    f.seek(sum(sizes), os.SEEK_CUR)
    return np.frombuffer(f.read(vertex.count * dtype.itemsize), dtype, vertex.count)


def _skip_ascii(tokens, pos, e, path) -> int:
    """The token index after the records of element `e`, which start at `pos`."""
    if not e.lists:
        return pos + e.count * len(e.props)
    for record in range(e.count):
        for name, word, _ in e.props:
            if word is None:
                if pos >= len(tokens) or not tokens[pos].isdigit():
                    raise PlyError(f"{path}: element {e.name!r} record {record}: list "
                                   f"{name!r} has no count")
                pos += int(tokens[pos])
            pos += 1
    return pos


def _ascii_vertices(f, path, before, vertex) -> dict:
    """The vertex columns of an ascii file, by property name."""
    props = vertex.types(path)
    tokens = f.read().split()
    pos = 0
    for e in before:
        pos = _skip_ascii(tokens, pos, e, path)
    n = len(props)
    if pos + vertex.count * n > len(tokens):
        raise PlyError(f"{path}: truncated: the vertex element needs {vertex.count * n} values "
                       f"for {vertex.count} vertices, the file has {max(0, len(tokens) - pos)} "
                       "after the elements before it")
    table = np.array(tokens[pos:pos + vertex.count * n], "S").reshape(vertex.count, n)
    columns = {}
    for j, (name, kind) in enumerate(props):
        try:
            columns[name] = table[:, j].astype(kind)
        except ValueError:
            bad = next(i for i, t in enumerate(table[:, j]) if not _parses(t, kind))
            raise PlyError(f"{path}: vertex {bad}: cannot parse {table[bad, j].decode()!r} as "
                           f"property {name!r} ({kind})") from None
    return columns


def _parses(token: bytes, kind: str) -> bool:
    """Whether an ascii value converts to the numpy type `kind`."""
    try:
        np.array([token]).astype(kind)
        return True
    except ValueError:
        return False


def _as_dtype(v, name, dtype, path):
    """Column `name` cast to `dtype`; finite values beyond dtype's range are refused."""
    col = v[name]
    if np.dtype(dtype).itemsize < col.dtype.itemsize:
        big = np.isfinite(col) & (np.abs(col) > np.finfo(dtype).max)
        if big.any():
            i = int(np.argmax(big))
            raise PlyError(f"{path}: {name} of vertex {i} ({col[i]:g}) is beyond {np.dtype(dtype)}"
                           "'s range; load the file as float64 (dtype=np.float64, with "
                           "jax_enable_x64)")
    return col.astype(dtype)


def load_ply(path, *, dtype=None) -> Gaussians:
    """Read an INRIA PLY into `Gaussians` (numpy arrays).

    `dtype`: None keeps the file's float precision (save_ply's files read back bit-identically);
    np.float32 or np.float64 casts every field to it (rounded to nearest; inf and NaN kept), and
    refuses a finite value beyond float32's range. Rendering float64 needs jax_enable_x64.
    Raises `PlyError` (a `ValueError`) naming the file and the problem, `OSError` for a file
    that cannot be opened.
    """
    if dtype is not None and np.dtype(dtype) not in (np.float32, np.float64):
        raise ValueError(f"dtype: expected np.float32 or np.float64 (or None: the file's), got "
                         f"{dtype!r}")
    path = os.fspath(path)
    with open(path, "rb") as f:
        fmt, before, vertex = _read_header(f, path)
        if fmt == "ascii":
            v = _ascii_vertices(f, path, before, vertex)
        else:
            v = _binary_vertices(f, path, fmt, before, vertex)
    return _gaussians(v, [n for n, _, _ in vertex.props], vertex.count, path, dtype)


def _gaussians(v, names, count, path, dtype) -> Gaussians:
    """`Gaussians` of the vertex columns `v` (by property name)."""
    missing = [n for n in _REQUIRED if n not in names]
    if missing:
        raise PlyError(f"{path}: missing required properties {missing}")
    n_rest = sum(1 for n in names if n.startswith("f_rest_"))
    if n_rest % 3 or n_rest // 3 + 1 not in SH_BASES:
        raise PlyError(f"{path}: {n_rest} f_rest properties is not 3·(K−1) for SH degree 0..3")
    missing = [f"f_rest_{i}" for i in range(n_rest) if f"f_rest_{i}" not in names]
    if missing:
        raise PlyError(f"{path}: missing properties {missing}")
    if dtype is None:
        dtype = np.result_type(*[v[n].dtype for n in _REQUIRED]).newbyteorder("=")
    col = lambda *ns: np.stack([_as_dtype(v, n, dtype, path) for n in ns], axis=-1)
    k = n_rest // 3 + 1
    rest = col(*[f"f_rest_{i}" for i in range(n_rest)]) if n_rest else np.zeros((count, 0), dtype)
    rest = rest.reshape(count, 3, k - 1)
    sh = np.concatenate([col("f_dc_0", "f_dc_1", "f_dc_2")[:, None, :],
                         rest.transpose(0, 2, 1)], axis=1)
    return Gaussians(means=col("x", "y", "z"), quats=col("rot_0", "rot_1", "rot_2", "rot_3"),
                     log_scales=col("scale_0", "scale_1", "scale_2"),
                     logit_opacities=_as_dtype(v, "opacity", dtype, path), sh=sh)


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
