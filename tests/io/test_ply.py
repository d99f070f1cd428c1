"""PLY and camera files: round trips, malformed files, and the real scenes."""

import json
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


def test_inria_cameras_match_stored_viewmats(data_dir):
    path = os.path.join(data_dir, "lego_sh3", "lego_cameras.json")
    cams = lgs_jax.load_cameras(path)
    meta = json.load(open(path))
    assert len(cams) == len(meta) == 100
    for cam, m in zip(cams[:5], meta[:5]):
        np.testing.assert_allclose(cam.viewmat, m["viewmat"], atol=1e-5)
        assert (cam.width, cam.height) == (800, 800)
    small = lgs_jax.load_cameras(path, width=200, height=200)[0]
    assert small.width == 200 and np.isclose(small.fx, meta[0]["fx"] / 4)


def test_nerf_transforms_convert_blender_axes(data_dir):
    path = os.path.join(data_dir, "lego_train", "transforms_train.json")
    cams = lgs_jax.load_cameras(path)
    assert (cams[0].width, cams[0].height) == (200, 200)  # read from the first image
    inria = lgs_jax.load_cameras(os.path.join(data_dir, "lego_sh3", "lego_cameras.json"))
    meta = json.load(open(path))
    by_name = {os.path.basename(f["file_path"]): i for i, f in enumerate(meta["frames"])}
    np.testing.assert_allclose(cams[by_name["r_0"]].viewmat, inria[0].viewmat, atol=1e-5)
    np.testing.assert_allclose(cams[0].fx * 4, inria[0].fx, rtol=1e-4)


@pytest.mark.parametrize("name,n,k", [("guitar/guitar.ply", 90854, 1),
                                      ("lego_sh3/lego_sh3.ply", 59999, 16),
                                      ("fruit_drops/fruit_drops_minimal.ply", 4721, 16)])
def test_real_scenes_load(data_dir, name, n, k):
    g = lgs_jax.load_ply(os.path.join(data_dir, name))
    assert g.means.shape == (n, 3) and g.sh.shape == (n, k, 3)
    if "guitar" in name:
        assert np.sum(g.logit_opacities == np.inf) == 667


def test_default_scene_is_bundled():
    g = lgs_jax.default_scene()
    assert g.means.shape == (4721, 3) and g.sh_degree == 3
    cam = lgs_jax.default_camera()
    assert (cam.width, cam.height) == (1280, 720)


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


INRIA = dict(id=0, width=64, height=36, position=[0.0, 0.0, -2.0],
             rotation=[[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], fx=50.0, fy=50.0)


def _cameras_file(tmp_path, cameras):
    path = tmp_path / "cameras.json"
    path.write_text(cameras if isinstance(cameras, str) else json.dumps(cameras))
    return path


@pytest.mark.parametrize("change,match", [
    (dict(fx=None), "camera 0: missing 'fx'"), (dict(rotation=None), "camera 0: missing 'rotation'"),
    (dict(fx="abc"), "camera 0: fx must be a finite number, got 'abc'"),
    (dict(width="640"), "camera 0: width must be a finite number, got '640'"),
    (dict(width=1280.7), "camera 0: width must be a positive whole number of pixels"),
    (dict(height=0), "camera 0: height must be a positive whole number"),
    (dict(rotation=[[1.0, 0], [0, 1.0]]), "camera 0: rotation must be 3x3 finite numbers"),
    (dict(rotation=[[1.0, 0, 0], [0, 1.2, 0], [0, 0, 1.0]]), "rotation is not orthonormal"),
    (dict(rotation=[[-1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]), "rotation is a reflection"),
    (dict(position=[0.0, 1.0]), "camera 0: position must be 3 finite numbers"),
    (dict(fy=True), "camera 0: fy must be a finite number, got True"),
])
def test_bad_inria_camera_field_names_file_camera_and_field(tmp_path, change, match):
    cam = {k: v for k, v in {**INRIA, **change}.items() if v is not None}
    path = _cameras_file(tmp_path, [INRIA, cam])
    with pytest.raises(ValueError, match=match.replace("camera 0", "camera 1")) as err:
        lgs_jax.load_cameras(path)
    assert str(path) in str(err.value)


def test_malformed_cameras_json_names_file_and_line(tmp_path):
    path = _cameras_file(tmp_path, '[{"fx": 1,\n}]')
    with pytest.raises(ValueError, match=r"cameras.json: not valid JSON: .*line 2"):
        lgs_jax.load_cameras(path)


def test_whole_number_float_size_is_accepted(tmp_path):
    cam = lgs_jax.load_cameras(_cameras_file(tmp_path, [{**INRIA, "width": 64.0}]))[0]
    assert cam.width == 64 and isinstance(cam.width, int)


def test_one_size_keeps_aspect_and_two_crop_the_centre(tmp_path):
    path = _cameras_file(tmp_path, [INRIA])
    (wide,) = lgs_jax.load_cameras(path, width=32)
    assert (wide.width, wide.height) == (32, 18) and wide.fx == wide.fy == 25.0
    (tall,) = lgs_jax.load_cameras(path, height=72)
    assert (tall.width, tall.height) == (128, 72) and tall.fx == tall.fy == 100.0
    (square,) = lgs_jax.load_cameras(path, width=36, height=36)  # cover: scale 1, crop x
    assert (square.width, square.height) == (36, 36) and square.fx == square.fy == 50.0
    assert (square.cx, square.cy) == (18.0, 18.0)
    with pytest.raises(ValueError, match="width: expected a positive int, got 0"):
        lgs_jax.load_cameras(path, width=0)


def test_resized_crop_shows_the_centre_of_the_view():
    """A point that projects to the centre column stays there, and one at the left edge of the
    wide view moves left of the cropped image by the cropped margin."""
    cam = lgs_jax.Camera(viewmat=np.eye(4, dtype=np.float32), fx=np.float32(50),
                         fy=np.float32(50), cx=np.float32(32), cy=np.float32(18), width=64,
                         height=36)
    crop = cam.resized(18, 18)  # scale 0.5 (height), then 32 -> 18 columns: 7 cut on each side
    assert float(crop.fx) == 25.0 and float(crop.cx) == 9.0 and float(crop.cy) == 9.0
    assert cam.resized() is cam


def _transforms(tmp_path, frames, image_size=None):
    if image_size:
        import matplotlib.image
        (tmp_path / "r_0.png").parent.mkdir(exist_ok=True)
        matplotlib.image.imsave(tmp_path / "r_0.png", np.zeros(image_size[::-1] + (3,)))
    path = tmp_path / "transforms.json"
    path.write_text(json.dumps(dict(camera_angle_x=0.69, frames=frames)))
    return path


def test_empty_nerf_frames_need_a_size(tmp_path):
    path = _transforms(tmp_path, [])
    with pytest.raises(ValueError, match="'frames' is empty.*pass width and height"):
        lgs_jax.load_cameras(path)
    with pytest.raises(ValueError, match="'frames' is empty"):
        lgs_jax.load_cameras(path, width=64)
    assert lgs_jax.load_cameras(path, width=64, height=64) == []


def test_nerf_width_alone_keeps_the_image_aspect(tmp_path):
    frame = dict(file_path="r_0", transform_matrix=np.eye(4).tolist())
    path = _transforms(tmp_path, [frame], image_size=(40, 20))
    assert (lgs_jax.load_cameras(path)[0].width, lgs_jax.load_cameras(path)[0].height) == (40, 20)
    cam = lgs_jax.load_cameras(path, width=20)[0]
    assert (cam.width, cam.height) == (20, 10)


@pytest.mark.parametrize("matrix,match", [
    (np.eye(3).tolist(), "frame 0: transform_matrix must be 4x4"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], "last row must be"),
    (np.diag([1, 2, 1, 1]).tolist(), "not orthonormal"),
])
def test_bad_nerf_transform_is_named(tmp_path, matrix, match):
    path = _transforms(tmp_path, [dict(file_path="r_0", transform_matrix=matrix)])
    with pytest.raises(ValueError, match=match):
        lgs_jax.load_cameras(path, width=8, height=8)


def test_default_camera_frames_the_label_and_orbit_views_stay():
    cam = lgs_jax.default_camera()
    assert (cam.width, cam.height) == (1280, 720)
    g = lgs_jax.default_scene()
    m = np.asarray(g.means, np.float64)
    t = m @ np.asarray(cam.viewmat, np.float64)[:3, :3].T + np.asarray(cam.viewmat)[:3, 3]
    u = cam.fx * t[:, 0] / t[:, 2] + cam.cx
    v = cam.fy * t[:, 1] / t[:, 2] + cam.cy
    inside = (u > 0) & (u < cam.width) & (v > 0) & (v < cam.height) & (t[:, 2] > 0)
    assert inside.mean() > 0.98  # the whole label in view ...
    assert np.ptp(np.percentile(u, [1, 99])) > 0.75 * cam.width  # ... filling the width
    assert lgs_jax.default_camera(None, width=320).height == 180
    assert lgs_jax.default_camera(7).width == 1280
    for bad in (-1, 8, 99):
        with pytest.raises(ValueError, match="orbit view 0..7"):
            lgs_jax.default_camera(bad)
