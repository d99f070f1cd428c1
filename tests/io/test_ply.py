"""lgs_jax.io.ply: INRIA PLY round trips, malformed files, and the real scenes."""

import os

import numpy as np
import pytest

import lgs_jax
from tests import scenes


@pytest.mark.parametrize("sh_bases", [1, 4, 9, 16])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_ply_round_trip_is_bit_identical(tmp_path, sh_bases, dtype):
    g = scenes.scene(1, sh_bases=sh_bases, dtype=dtype)
    path = tmp_path / "s.ply"
    lgs_jax.save_ply(path, g)
    back = lgs_jax.load_ply(path)
    for name in ("means", "quats", "log_scales", "logit_opacities", "sh"):
        a, b = np.asarray(getattr(g, name)), np.asarray(getattr(back, name))
        assert a.dtype == b.dtype and a.shape == b.shape
        assert a.tobytes() == b.tobytes(), name  # NaN and inf included


def _write(path, header, body=b""):
    path.write_bytes(("\n".join(header) + "\n").encode() + body)
    return path


GOOD = ["ply", "format binary_little_endian 1.0", "element vertex 1"] + [
    f"property float {n}" for n in
    ["opacity", "rot_0", "rot_1", "rot_2", "rot_3", "x", "y", "z", "extra", "f_dc_0", "f_dc_1",
     "f_dc_2", "scale_0", "scale_1", "scale_2"]] + ["end_header"]


def test_ply_reads_by_name_in_any_order_and_ignores_extras(tmp_path):
    values = np.arange(15, dtype="<f4")
    g = lgs_jax.load_ply(_write(tmp_path / "a.ply", GOOD, values.tobytes()))
    np.testing.assert_array_equal(g.means[0], [5, 6, 7])
    np.testing.assert_array_equal(g.quats[0], [1, 2, 3, 4])
    np.testing.assert_array_equal(g.sh[0, 0], [9, 10, 11])
    assert g.logit_opacities[0] == 0 and g.sh.shape == (1, 1, 3)


@pytest.mark.parametrize("case,match", [
    ("notply", "not a PLY"), ("format", "format 'binary_middle_endian' is not supported"),
    ("missing", "scale_2"),
    ("truncated", "truncated"), ("noend", "end_header"), ("badrest", "f_rest"),
])
def test_malformed_ply_says_why(tmp_path, case, match):
    body = np.zeros(15, "<f4").tobytes()
    header = list(GOOD)
    if case == "notply":
        header[0] = "obj"
    elif case == "format":
        header[1] = "format binary_middle_endian 1.0"
    elif case == "missing":
        header.remove("property float scale_2")
        body = body[:-4]
    elif case == "truncated":
        body = body[:-1]
    elif case == "noend":
        header = header[:-1]
        body = b""
    elif case == "badrest":
        header.insert(-1, "property float f_rest_0")
        body += b"\0\0\0\0"
    with pytest.raises(lgs_jax.PlyError, match=match):
        lgs_jax.load_ply(_write(tmp_path / "bad.ply", header, body))


@pytest.mark.parametrize("name,n,k", [("guitar/guitar.ply", 90854, 1),
                                      ("lego_sh3/lego_sh3.ply", 59999, 16),
                                      ("fruit_drops/fruit_drops_minimal.ply", 4721, 16)])
def test_real_scenes_load(data_dir, name, n, k):
    g = lgs_jax.load_ply(os.path.join(data_dir, name))
    assert g.means.shape == (n, 3) and g.sh.shape == (n, k, 3)
    if "guitar" in name:
        assert np.sum(g.logit_opacities == np.inf) == 667


@pytest.mark.parametrize("line,match", [
    ("element vertex -1", "vertex count"), ("element vertex -5", "vertex count"),
    ("element vertex abc", "vertex count"), ("element vertex", "vertex count"),
])
def test_bad_vertex_count_says_why(tmp_path, line, match):
    header = [line if h.startswith("element vertex") else h for h in GOOD]
    with pytest.raises(lgs_jax.PlyError, match=match):
        lgs_jax.load_ply(_write(tmp_path / "bad.ply", header, np.zeros(15, "<f4").tobytes()))


def test_header_cut_mid_line_says_so(tmp_path):
    path = tmp_path / "cut.ply"
    path.write_bytes("\n".join(GOOD[:6]).encode() + b"\nproperty f")
    with pytest.raises(lgs_jax.PlyError, match=r"header cut off in line 7 \(b.property f.; no end_header\)"):
        lgs_jax.load_ply(path)


def test_property_line_without_name_says_so(tmp_path):
    header = GOOD[:-1] + ["property float", "end_header"]
    with pytest.raises(lgs_jax.PlyError, match="not 'property TYPE NAME'"):
        lgs_jax.load_ply(_write(tmp_path / "bad.ply", header))


def test_missing_or_directory_ply_raises_os_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        lgs_jax.load_ply(tmp_path / "missing.ply")
    with pytest.raises(IsADirectoryError):
        lgs_jax.load_ply(tmp_path)


# --- other elements, formats and precisions -------------------------------------------------------

EXTRA = ["element extra 10", "property float a", "property float b", "property float c"]
FACE = ["element face 2", "property list uchar int vertex_indices"]
VALUES = np.arange(15, dtype="<f4") + 0.5  # one vertex in GOOD's property order


def _layout(before=(), after=(), fmt="binary_little_endian"):
    """GOOD's header with `fmt` and the element lines `before` and `after` the vertex element."""
    vertex_end = GOOD.index("end_header")
    return (GOOD[:1] + [f"format {fmt} 1.0"] + list(before) + GOOD[2:vertex_end] + list(after)
            + ["end_header"])


def _assert_good_vertex(g):
    np.testing.assert_array_equal(g.means[0], [5.5, 6.5, 7.5])
    np.testing.assert_array_equal(g.quats[0], [1.5, 2.5, 3.5, 4.5])
    np.testing.assert_array_equal(g.sh[0, 0], [9.5, 10.5, 11.5])
    np.testing.assert_array_equal(g.log_scales[0], [12.5, 13.5, 14.5])
    assert g.logit_opacities[0] == 0.5 and g.means.dtype == np.float32


def test_binary_elements_before_and_after_vertex_are_skipped_by_their_sizes(tmp_path):
    extra = np.full(30, 99, "<f4").tobytes()
    faces = (b"\x03" + np.arange(3, dtype="<i4").tobytes()) * 2
    body = extra + VALUES.tobytes() + faces
    _assert_good_vertex(lgs_jax.load_ply(_write(tmp_path / "a.ply", _layout(EXTRA, FACE), body)))
    big = VALUES.astype(">f4").tobytes()
    path = _write(tmp_path / "b.ply", _layout(fmt="binary_big_endian"), big)
    _assert_good_vertex(lgs_jax.load_ply(path))
    assert lgs_jax.load_ply(path).means.dtype == np.dtype("=f4")  # native byte order


def _ascii(values):
    return "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in values).encode()


def test_ascii_ply_reads_with_elements_before_and_after_vertex(tmp_path):
    extra = _ascii(np.full((10, 3), 99.0))
    faces = b"3 0 1 2\n4 0 1 2 3\n"
    before = EXTRA + FACE
    body = extra + faces + _ascii(VALUES[None]) + faces
    path = _write(tmp_path / "a.ply", _layout(before, FACE, fmt="ascii"), body)
    _assert_good_vertex(lgs_jax.load_ply(path))


@pytest.mark.parametrize("sh_bases", [1, 16])
def test_ascii_ply_equals_the_binary_file(tmp_path, sh_bases):
    g = scenes.scene(1, sh_bases=sh_bases, dtype=np.float32)
    lgs_jax.save_ply(tmp_path / "s.ply", g)
    data = (tmp_path / "s.ply").read_bytes()
    head, body = data.split(b"end_header\n")
    names = [line.split()[-1] for line in head.decode().splitlines() if line.startswith("property")]
    rows = np.frombuffer(body, [(n, "<f4") for n in names])
    text = b"".join(b" ".join(b"%.9g" % v for v in row) + b"\n" for row in rows.tolist())
    ascii_head = head.replace(b"binary_little_endian", b"ascii")
    (tmp_path / "a.ply").write_bytes(ascii_head + b"end_header\n" + text)
    a, b = lgs_jax.load_ply(tmp_path / "a.ply"), lgs_jax.load_ply(tmp_path / "s.ply")
    for name in ("means", "quats", "log_scales", "logit_opacities", "sh"):
        assert np.asarray(getattr(a, name)).tobytes() == np.asarray(getattr(b, name)).tobytes()


@pytest.mark.parametrize("before,body,match", [
    (FACE, b"", "element 'face' before vertex has the list property 'vertex_indices'"),
    (["element extra 1", "property half a"], b"", "unknown property type 'half'"),
    (["element extra 2000000000"] + EXTRA[1:], b"",
     r"truncated: element 'extra' \(2000000000 records\) and 1 vertices need 24000000060 bytes"),
])
def test_binary_elements_that_cannot_be_sized_or_read_are_refused(tmp_path, before, body, match):
    path = _write(tmp_path / "bad.ply", _layout(before), body + VALUES.tobytes())
    with pytest.raises(lgs_jax.PlyError, match=match):
        lgs_jax.load_ply(path)


def test_vertex_count_beyond_the_file_is_refused_before_reading(tmp_path):
    header = [h.replace("vertex 1", f"vertex {2**40}") for h in GOOD]
    with pytest.raises(lgs_jax.PlyError, match=r"truncated: .*1099511627776 vertices need "
                                               r"65970697666560 bytes.*has 60"):
        lgs_jax.load_ply(_write(tmp_path / "big.ply", header, VALUES.tobytes()))


@pytest.mark.parametrize("body,match", [
    (b"1 2 3\n", "truncated: .*15 values for 1 vertices"),
    (b"1 2 x 4 5 6 7 8 9 10 11 12 13 14 15\n", "vertex 0: cannot parse 'x'"),
])
def test_bad_ascii_data_says_where(tmp_path, body, match):
    with pytest.raises(lgs_jax.PlyError, match=match):
        lgs_jax.load_ply(_write(tmp_path / "bad.ply", _layout(fmt="ascii"), body))


def test_float64_ply_loads_as_float32_on_request(tmp_path):
    g = scenes.scene(1, sh_bases=16, dtype=np.float64)
    lgs_jax.save_ply(tmp_path / "d.ply", g)
    assert lgs_jax.load_ply(tmp_path / "d.ply").means.dtype == np.float64  # the file's precision
    f = lgs_jax.load_ply(tmp_path / "d.ply", dtype=np.float32)
    for name in ("means", "quats", "log_scales", "logit_opacities", "sh"):
        want = np.asarray(getattr(g, name)).astype(np.float32)  # round to nearest; inf, NaN kept
        assert np.asarray(getattr(f, name)).tobytes() == want.tobytes(), name
    up = lgs_jax.load_ply(tmp_path / "d.ply", dtype=np.float64)
    assert up.means.dtype == np.float64
    with pytest.raises(ValueError, match="dtype: expected np.float32 or np.float64"):
        lgs_jax.load_ply(tmp_path / "d.ply", dtype=np.int32)


def test_float64_values_beyond_float32_are_refused_when_cast(tmp_path):
    g = scenes.scene(1, sh_bases=1, dtype=np.float64)
    g.log_scales[0, 1] = 1e300
    lgs_jax.save_ply(tmp_path / "d.ply", g)
    with pytest.raises(lgs_jax.PlyError, match=r"d.ply: scale_1 of vertex 0 \(1e\+300\) is beyond "
                                               "float32's range"):
        lgs_jax.load_ply(tmp_path / "d.ply", dtype=np.float32)
