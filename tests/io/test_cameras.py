"""lgs_jax.io.cameras: INRIA cameras.json and NeRF transforms.json, sizes (aspect kept, centre
crop), and bad files naming the file, camera and field."""

import json
import os

import numpy as np
import pytest

import lgs_jax


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


INRIA = dict(id=0, width=64, height=36, position=[0.0, 0.0, -2.0],
             rotation=[[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], fx=50.0, fy=50.0)


def _cameras_file(tmp_path, cameras):
    path = tmp_path / "cameras.json"
    path.write_text(cameras if isinstance(cameras, str) else json.dumps(cameras))
    return path


@pytest.mark.parametrize("change,match", [
    (dict(fx=None), "camera 0: missing 'fx'"), (dict(rotation=None), "camera 0: missing 'rotation'"),
    (dict(fx="abc"), "camera 0: fx must be a finite number > 0, got 'abc'"),
    (dict(fx=0.0), "camera 0: fx must be a finite number > 0, got 0.0"),
    (dict(width="640"), "camera 0: width must be a finite number, got '640'"),
    (dict(width=1280.7), "camera 0: width must be a positive whole number of pixels"),
    (dict(height=0), "camera 0: height must be a positive whole number"),
    (dict(rotation=[[1.0, 0], [0, 1.0]]), "camera 0: rotation must be 3x3 finite numbers"),
    (dict(rotation=[[1.0, 0, 0], [0, 1.2, 0], [0, 0, 1.0]]), "rotation is not orthonormal"),
    (dict(rotation=[[-1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]), "rotation is a reflection"),
    (dict(position=[0.0, 1.0]), "camera 0: position must be 3 finite numbers"),
    (dict(fy=True), "camera 0: fy must be a finite number > 0, got True"),
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
    (np.eye(3).tolist(), r"frame 0 \(r_0\): transform_matrix must be 4x4"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], "last row must be"),
    (np.diag([1, 2, 1, 1]).tolist(), "not orthonormal"),
])
def test_bad_nerf_transform_is_named(tmp_path, matrix, match):
    path = _transforms(tmp_path, [dict(file_path="r_0", transform_matrix=matrix)])
    with pytest.raises(ValueError, match=match):
        lgs_jax.load_cameras(path, width=8, height=8)


def test_saved_cameras_load_back(tmp_path):
    """save_cameras writes INRIA cameras.json that load_cameras reads back (to float32)."""
    cams = [lgs_jax.default_camera(v) for v in range(8)] + [lgs_jax.default_camera(None, 64, 48)]
    path = tmp_path / "cameras.json"
    lgs_jax.save_cameras(path, cams, [f"v{i}" for i in range(9)])
    back = lgs_jax.load_cameras(path)
    assert [c["img_name"] for c in json.load(open(path))] == [f"v{i}" for i in range(9)]
    for a, b in zip(cams, back):
        np.testing.assert_allclose(np.asarray(b.viewmat), np.asarray(a.viewmat), atol=1e-6)
        assert (a.width, a.height) == (b.width, b.height)
        for name in ("fx", "fy", "cx", "cy"):
            assert float(getattr(b, name)) == float(getattr(a, name))


def _same_camera(a, b):
    assert (a.width, a.height) == (b.width, b.height)
    for name in ("viewmat", "fx", "fy", "cx", "cy"):
        assert np.asarray(getattr(a, name)).tobytes() == np.asarray(getattr(b, name)).tobytes(), \
            name


def test_transforms_cameras_are_the_dataset_cameras(tmp_path):
    """load_cameras reads transforms.json with the dataset loader's parser: fl_x, fl_y, cx, cy,
    w, h and per-frame overrides."""
    from tests.io.captures import write_frames

    c2w = np.eye(4)
    c2w[:3, 3] = [1.0, 2.0, 3.0]
    frames = [dict(file_path="images/a.png", transform_matrix=c2w.tolist()),
              dict(file_path="images/b.png", transform_matrix=np.eye(4).tolist(), fl_x=60.0,
                   cx=21.5)]
    path = write_frames(tmp_path, dict(fl_x=50.0, fl_y=55.0, cx=19.0, cy=16.0), frames)
    cams = lgs_jax.load_cameras(path)
    assert [(c.fx, c.fy, c.cx, c.cy, c.width, c.height) for c in cams] == \
        [(50.0, 55.0, 19.0, 16.0, 40, 30), (60.0, 55.0, 21.5, 16.0, 40, 30)]
    for a, b in zip(cams, lgs_jax.load_dataset(tmp_path).cameras):
        _same_camera(a, b)
    (half,) = lgs_jax.load_cameras(path, width=20)[:1]  # Camera.resized, as for cameras.json
    _same_camera(half, cams[0].resized(20))


@pytest.mark.parametrize("content,says", [
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n\x00\xff\xfe",
     "is a PLY file, not a cameras file"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\xff", "not a cameras file: not UTF-8 text"),
])
def test_a_binary_file_as_cameras_says_it_is_not_a_cameras_file(tmp_path, content, says):
    path = tmp_path / "scene.ply"
    path.write_bytes(content)
    with pytest.raises(lgs_jax.DatasetError, match=says) as e:
        lgs_jax.load_cameras(path)
    assert str(e.value).startswith(str(path))
