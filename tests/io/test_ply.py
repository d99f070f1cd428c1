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
    ("notply", "not a PLY"), ("ascii", "binary_little_endian"), ("missing", "scale_2"),
    ("truncated", "truncated"), ("noend", "end_header"), ("badrest", "f_rest"),
])
def test_malformed_ply_says_why(tmp_path, case, match):
    body = np.zeros(15, "<f4").tobytes()
    header = list(GOOD)
    if case == "notply":
        header[0] = "obj"
    elif case == "ascii":
        header[1] = "format ascii 1.0"
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
