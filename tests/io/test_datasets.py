"""lgs_jax.load_dataset: COLMAP and transforms.json readers against independent readings, lens
undistortion on synthetic images with known distortion, bad datasets, and the real captures."""

import json
import math
import os
import sys

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

import lgs_jax
from lgs_jax.io import colmap, undistort
from lgs_jax.io.datasets import as_float
from lgs_jax.io.views import Lens
from tests.io import colmap_format as cf
from tests.io.captures import tiny_colmap, tiny_transforms, write_frames


# --- an independent transcription of the lens model (views.Lens's docstring) ---------------------

def distort(x, y, d):
    k1, k2, p1, p2, k3 = d
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def undistort_points(xd, yd, d, iters=200):
    """Inverse of `distort` by fixed-point iteration (converges for the moderate lenses here)."""
    x, y = xd, yd
    for _ in range(iters):
        dx, dy = distort(x, y, d)
        x, y = x + (xd - dx), y + (yd - dy)
    assert np.abs(np.stack(distort(x, y, d)) - np.stack([xd, yd])).max() < 1e-12
    return x, y


def pixel_grid(fx, fy, cx, cy, w, h):
    """Normalised (distorted) coordinates of every pixel centre (j + 0.5, i + 0.5)."""
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    return (u - cx) / fx, (v - cy) / fy


PERIOD = 0.25  # of the test pattern, in normalised units (about 25 pixels here)


def pattern(x, y):
    """A smooth checkerboard on the undistorted image plane: its zero lines (value 0.5) are the
    straight lines x = n·PERIOD/2 and y = m·PERIOD/2."""
    return 0.5 + 0.45 * np.sin(2 * np.pi * x / PERIOD) * np.sin(2 * np.pi * y / PERIOD)


def render_distorted(lens):
    """8-bit RGB image of `pattern` taken through `lens` (fx, fy, cx, cy, w, h, dist)."""
    fx, fy, cx, cy, w, h, dist = lens
    x, y = undistort_points(*pixel_grid(fx, fy, cx, cy, w, h), dist)
    return np.repeat(np.round(255 * pattern(x, y)).astype(np.uint8)[..., None], 3, -1)


def render_pinhole(cam):
    return pattern(*pixel_grid(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height))


# --- COLMAP --------------------------------------------------------------------------------------

def skull(data_dir):
    path = os.path.join(data_dir, "skull")
    if not os.path.isdir(path):
        pytest.skip("skull not found")
    return path


def assert_model_equals(model, cameras, images, points):
    """A library `ColmapModel` equals the independent reading (cameras, images, points)."""
    assert {c.id: (c.model, c.width, c.height, c.params) for c in model.cameras.values()} == \
        {c[0]: (cf.MODEL_NAMES[c[1]], c[2], c[3], c[4]) for c in cameras}
    assert {i.id: (i.qvec, i.tvec, i.camera_id, i.name) for i in model.images.values()} == \
        {i[0]: (i[1], i[2], i[3], i[4]) for i in images}
    np.testing.assert_array_equal(model.point_ids, [p[0] for p in points])
    np.testing.assert_array_equal(model.points, np.reshape([p[1] for p in points], (-1, 3)))
    np.testing.assert_array_equal(model.colors, np.reshape([p[2] for p in points], (-1, 3)))
    np.testing.assert_array_equal(model.errors, [p[3] for p in points])


def test_skull_model_equals_an_independent_reading_and_its_text_form(data_dir, tmp_path):
    folder = os.path.join(skull(data_dir), "sparse", "0")
    cameras, images, points = cf.read_bin(folder)
    assert len(cameras) == 1 and len(images) == 66 and len(points) == 11582
    assert_model_equals(colmap.read_model(folder), cameras, images, points)
    cf.write_txt(tmp_path, cameras, images, points)  # text written from the binary, read back
    assert_model_equals(colmap.read_model(tmp_path), cameras, images, points)
    model = colmap.read_model(folder)
    for im in images:  # the library's rotation against scipy's (quaternion w, x, y, z)
        want = Rotation.from_quat([*im[1][1:], im[1][0]]).as_matrix()
        np.testing.assert_allclose(colmap.quat_to_rotation(model.images[im[0]].qvec), want,
                                   atol=1e-12)


# Cameras of every supported model, with known parameters; sizes differ per camera.
LENSES = {  # model id: (params, width, height)
    0: ((80.0, 41.0, 29.5), 80, 60),
    1: ((84.0, 90.0, 44.0, 31.0), 88, 64),
    2: ((90.0, 50.0, 37.0, -0.2), 100, 75),
    3: ((100.0, 58.0, 44.0, 0.15, -0.05), 120, 90),
    4: ((95.0, 105.0, 54.0, 40.0, -0.1, 0.02, 0.004, -0.003), 110, 84),
}


def lens_of(model, params, w, h):
    """(fx, fy, cx, cy, w, h, (k1, k2, p1, p2, k3)) of COLMAP's models, transcribed."""
    if model in (0, 2, 3):
        f, cx, cy, *k = params
        return f, f, cx, cy, w, h, tuple(k) + (0.0,) * (5 - len(k))  # radial k1 (k2)
    fx, fy, cx, cy, *d = params
    return fx, fy, cx, cy, w, h, tuple(d) + (0.0,) * (5 - len(d))  # OPENCV: k1 k2 p1 p2


def generated_model(root, fmt):
    """A COLMAP dataset with one camera and image per model in LENSES, images of `pattern`."""
    rng = np.random.default_rng(0)
    cameras, images = [], []
    for cid, (model, (params, w, h)) in enumerate(LENSES.items(), 1):
        cameras.append((cid, model, w, h, params))
        q = rng.normal(size=4)
        xys = [(1.5, 2.5, 1), (3.0, 4.0, cf.NO_POINT)] if cid == 1 else []  # and empty lines
        images.append((10 + cid, tuple((q / np.linalg.norm(q)).tolist()),
                       tuple(rng.normal(size=3).tolist()), cid, f"cam{cid}.png", xys))
        os.makedirs(os.path.join(root, "images"), exist_ok=True)
        Image.fromarray(render_distorted(lens_of(model, params, w, h))).save(
            os.path.join(root, "images", f"cam{cid}.png"))
    points = [(1, (0.5, -1.0, 2.0), (255, 128, 0), 0.7, [(11, 0)]),
              (7, (1.0, 2.0, 3.0), (0, 0, 1), 0.1, [])]
    write = cf.write_bin if fmt == "bin" else cf.write_txt
    write(os.path.join(root, "sparse", "0"), cameras, images, points)
    return images


@pytest.mark.parametrize("fmt", ["bin", "txt"])
def test_generated_models_of_every_camera_type_undistort_to_the_pinhole_image(tmp_path, fmt):
    images = generated_model(tmp_path, fmt)
    d = lgs_jax.load_dataset(tmp_path)
    assert d.names == tuple(f"cam{i}.png" for i in range(1, 6))
    assert isinstance(d.images, list)  # sizes differ
    np.testing.assert_array_equal(d.points, [[0.5, -1.0, 2.0], [1.0, 2.0, 3.0]])
    np.testing.assert_allclose(d.colors, [[1, 128 / 255, 0], [0, 0, 1 / 255]], atol=1e-7)
    for (_, q, t, cid, _, _), img, cam in zip(images, d.images, d.cameras):
        want = np.eye(4)
        want[:3, :3], want[:3, 3] = Rotation.from_quat([*q[1:], q[0]]).as_matrix(), t
        np.testing.assert_allclose(cam.viewmat, want, atol=1e-6)
        model = list(LENSES)[cid - 1]
        fx, fy, cx, cy, w, h, dist = lens_of(model, *LENSES[model])
        assert (cam.fx, cam.fy) == (np.float32(fx), np.float32(fy))  # focal lengths kept
        if not any(dist):  # pinhole: untouched
            assert (cam.cx, cam.cy, cam.width, cam.height) == (np.float32(cx), np.float32(cy), w, h)
        assert img.shape == (cam.height, cam.width, 3)
        err = np.abs(img[..., 0] - render_pinhole(cam))
        # bilinear resampling of a 25-pixel period and 8 bits give < 0.013 here; an intrinsic
        # half a pixel off gives > 0.05.
        assert err.max() < 0.025, (model, err.max())


# --- undistortion ---------------------------------------------------------------------------------

STRONG = {"barrel": (-0.3, 0.08, 0.0, 0.0, 0.0), "pincushion": (0.25, 0.05, 0.0, 0.0, 0.0),
          "tangential": (-0.1, 0.02, 0.01, -0.008, 0.0), "k3": (-0.2, 0.0, 0.0, 0.0, 0.05),
          "fox": (0.0578421, -0.0805099, -0.000980296, 0.00015575, 0.0)}


@pytest.mark.parametrize("kind", STRONG)
def test_undistorted_crop_has_no_invalid_pixel_and_is_tight(kind):
    lens = Lens(300.0, 310.0, 163.0, 118.0, 320, 240, STRONG[kind])
    new, _ = undistort.undistorter(lens, "test")
    assert not new.distorted and new.fx == lens.fx and new.fy == lens.fy

    def sources(pad):
        """Source pixel coordinates of the new image's pixel centres, grown by `pad` pixels."""
        u = np.arange(-pad, new.width + pad) + 0.5
        v = np.arange(-pad, new.height + pad) + 0.5
        u, v = np.meshgrid(u, v)
        xd, yd = distort((u - new.cx) / new.fx, (v - new.cy) / new.fy, lens.dist)
        return xd * lens.fx + lens.cx, yd * lens.fy + lens.cy

    su, sv = sources(0)
    assert su.min() >= 0 and su.max() <= lens.width and sv.min() >= 0 and sv.max() <= lens.height
    gu, gv = sources(2)  # two more pixels on any side leave the image
    assert gu[:, :2].min() < 0 and gu[:, -2:].max() > lens.width
    assert gv[:2].min() < 0 and gv[-2:].max() > lens.height


def line_fit_residual(points):
    """Largest distance (pixels) of 2D points from their total-least-squares line."""
    p = np.asarray(points) - np.mean(points, 0)
    return np.abs(p @ np.linalg.svd(p)[2][1]).max()


def zero_crossings(signal):
    """Sub-pixel positions (pixel-centre coordinates) where a 1D signal crosses 0.5."""
    s = signal - 0.5
    k = np.flatnonzero(np.sign(s[:-1]) * np.sign(s[1:]) < 0)
    return k + 0.5 + s[k] / (s[k] - s[k + 1])


def test_undistortion_straightens_the_lines_of_a_checkerboard(tmp_path):
    """A transforms.json camera with k1, k2, p1, p2; the board's straight lines, bent in the
    image, come out straight and where the pinhole camera puts them."""
    fx, fy, cx, cy, w, h = 300.0, 300.0, 163.0, 118.0, 320, 240
    dist = (-0.25, 0.08, 0.004, -0.003, 0.0)
    os.makedirs(tmp_path / "images")
    Image.fromarray(render_distorted((fx, fy, cx, cy, w, h, dist))).save(tmp_path / "images/a.png")
    meta = dict(fl_x=fx, fl_y=fy, cx=cx, cy=cy, w=w, h=h, k1=dist[0], k2=dist[1], p1=dist[2],
                p2=dist[3], frames=[dict(file_path="images/a.png", transform_matrix=np.eye(4)
                                         .tolist())])
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    d = lgs_jax.load_dataset(tmp_path)
    cam, img = d.cameras[0], d.images[0][..., 0]
    (same,) = lgs_jax.load_cameras(tmp_path / "transforms.json")  # the undistorted camera
    assert (same.width, same.height, same.fx, same.cx, same.cy) == \
        (cam.width, cam.height, cam.fx, cam.cx, cam.cy)
    half, bent = PERIOD / 2, []
    for axis in (0, 1):  # 0: vertical lines, crossed along rows; 1: horizontal, along columns
        f, c = (cam.fx, cam.cx) if axis == 0 else (cam.fy, cam.cy)
        g, e = (cam.fy, cam.cy) if axis == 0 else (cam.fx, cam.cx)
        lines = {}
        for k, line in enumerate(img if axis == 0 else img.T):
            if abs(np.sin(2 * np.pi * (k + 0.5 - e) / g / PERIOD)) < 0.5:
                continue  # near a line across: too little signal
            for pos in zero_crossings(line):
                lines.setdefault(round((pos - c) / f / half), []).append((pos, k + 0.5))
        assert len(lines) >= 6
        for n, pts in lines.items():
            assert line_fit_residual(pts) < 0.1  # straight
            assert np.abs(np.asarray(pts)[:, 0] - (f * n * half + c)).max() < 0.1  # in place
            # the same stretch of line in the distorted input
            t = (np.linspace(*np.asarray(pts)[[0, -1], 1], 50) - e) / g
            x, y = (np.full_like(t, n * half), t) if axis == 0 else (t, np.full_like(t, n * half))
            xd, yd = distort(x, y, dist)
            bent.append(line_fit_residual(np.stack([xd * fx + cx, yd * fy + cy], 1)))
    assert max(bent) > 2  # the input's lines were visibly bent


# --- transforms.json ------------------------------------------------------------------------------

def test_transforms_camera_projects_a_point_where_computed_by_hand(tmp_path):
    """Camera 5 units up the world z axis, looking down at the origin (OpenGL axes: camera y is
    world y, the camera looks along −z). The point (1, 0.5, 0) is 5 in front, 1 right, 0.5 up:
    u = fx·1/5 + cx, v = cy − fy·0.5/5."""
    c2w = np.eye(4)
    c2w[2, 3] = 5.0
    frames = [dict(file_path="images/a.png", transform_matrix=c2w.tolist()),
              dict(file_path="images/b.png", transform_matrix=c2w.tolist(), fl_x=60.0, fl_y=70.0,
                   cx=21.0, cy=14.0),
              dict(file_path="images/c.png", transform_matrix=c2w.tolist(),
                   camera_angle_y=2 * math.atan(0.25))]
    # frame a: the shared intrinsics; camera_angle_x = 2·atan(0.5) gives fx = w = 40, fy = fx;
    # frame b: its own; frame c: fy = 0.5·h / tan(0.5·camera_angle_y) = 15 / 0.25.
    write_frames(tmp_path, dict(camera_angle_x=2 * math.atan(0.5)), frames)
    d = lgs_jax.load_dataset(tmp_path)
    point = np.array([1.0, 0.5, 0.0, 1.0])
    for cam, (fx, fy, cx, cy) in zip(d.cameras, [(40, 40, 20, 15), (60, 70, 21, 14),
                                                 (40, 60, 20, 15)]):
        assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (fx, fy, cx, cy, 40, 30)
        p = np.asarray(cam.viewmat, np.float64) @ point
        assert p[2] == pytest.approx(5.0)
        u, v = cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy
        assert (u, v) == (pytest.approx(fx / 5 + cx), pytest.approx(cy - fy * 0.5 / 5))
    assert d.points.shape == d.colors.shape == (0, 3)
    np.testing.assert_array_equal(d.background, [0, 0, 0])
    np.testing.assert_allclose(d.images[0, 0, 0], np.array([10, 20, 30]) / 255, atol=1e-7)


def test_downscale_averages_blocks_and_divides_intrinsics(tmp_path):
    frames = [dict(file_path="images/a.png", transform_matrix=np.eye(4).tolist())]
    write_frames(tmp_path, dict(fl_x=50.0, cx=19.0, cy=16.0), frames, size=(41, 31))
    rng = np.random.default_rng(1)
    pixels = rng.integers(0, 256, (31, 41, 3), np.uint8)
    Image.fromarray(pixels).save(tmp_path / "images" / "a.png")
    d = lgs_jax.load_dataset(tmp_path, downscale=3)
    cam = d.cameras[0]
    assert (cam.width, cam.height) == (13, 10)  # 41 // 3, 31 // 3: last column and row dropped
    assert (cam.fx, cam.cx, cam.cy) == (np.float32(50 / 3), np.float32(19 / 3), np.float32(16 / 3))
    want = pixels[:30, :39].reshape(10, 3, 13, 3, 3).mean((1, 3)) / 255
    np.testing.assert_allclose(d.images[0], want, atol=1e-6)
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="downscale"):
            lgs_jax.load_dataset(tmp_path, downscale=bad)
    # 8-bit images: exactly the file's values at full size, the nearest x/255 after downscaling
    full, u8 = (lgs_jax.load_dataset(tmp_path, dtype=t) for t in (np.float32, np.uint8))
    assert u8.images.dtype == np.uint8 and full.images.dtype == np.float32
    np.testing.assert_array_equal(u8.images[0], pixels)
    np.testing.assert_array_equal(as_float(u8.images), full.images)  # the same bits
    small = lgs_jax.load_dataset(tmp_path, downscale=3, dtype=np.uint8)
    np.testing.assert_array_equal(small.images[0], np.round(want * 255))
    for bad in (np.float64, "int8", 3):
        with pytest.raises(ValueError, match='dtype: expected np.float32, np.uint8 or "auto"'):
            lgs_jax.load_dataset(tmp_path, dtype=bad)


# --- bad datasets --------------------------------------------------------------------------------

def _truncate(path):
    data = open(path, "rb").read()
    open(path, "wb").write(data[:-5])


def _garbage(path):
    open(path, "wb").write(b"not an image")


def _text_model(root, cameras_line):
    tiny_colmap(root)
    cameras, images, points = cf.read_bin(os.path.join(root, "sparse", "0"))
    for ext in ("cameras", "images", "points3D"):
        os.remove(os.path.join(root, "sparse", "0", ext + ".bin"))
    cf.write_txt(os.path.join(root, "sparse", "0"), cameras, images, points)
    open(os.path.join(root, "sparse", "0", "cameras.txt"), "a").write(cameras_line + "\n")


BAD = {  # case: (make the dataset in root, file the message names, what it says)
    "colmap missing image": (lambda r: (tiny_colmap(r), os.remove(f"{r}/images/b.png")),
                             "images/b.png", r"image not found \(listed in .*images.bin\)"),
    "transforms missing image": (lambda r: (tiny_transforms(r, w=40, h=30),
                                            os.remove(f"{r}/images/a.png")),
                                 "images/a.png",
                                 r"image not found \(listed in .*transforms.json\)"),
    "unsupported model": (lambda r: tiny_colmap(r, model=(6, (1.0,) * 12)),
                          "sparse/0/cameras.bin",
                          "camera 1 has the unsupported camera model FULL_OPENCV"),
    "fisheye transforms": (lambda r: tiny_transforms(r, is_fisheye=True), "transforms.json",
                           "unsupported camera model"),
    "unknown text model": (lambda r: _text_model(r, "2 FOO 8 6 1 2 3"), "sparse/0/cameras.txt",
                           "camera 2 has unknown camera model FOO"),
    "bad text line": (lambda r: _text_model(r, "3 PINHOLE 8 6 1 2"), "sparse/0/cameras.txt:3",
                      "cannot parse a camera"),
    "colmap wrong size": (lambda r: (tiny_colmap(r), Image.new("RGB", (9, 6)).save(
        f"{r}/images/b.png")), "images/b.png", "image is 9x6 pixels but its camera in "
                                               ".*cameras.bin is 8x6"),
    "transforms wrong size": (lambda r: tiny_transforms(r, w=50, h=30), "images/a.png",
                              "image is 40x30 pixels but its camera in .*transforms.json is 50x30"),
    "empty model": (lambda r: tiny_colmap(r, images=()), "sparse/0/images.bin",
                    r"the model has no images \(empty model\)"),
    "unknown camera": (lambda r: tiny_colmap(r, camera_id=9), "sparse/0/images.bin",
                       "image 'a.png' uses camera 9, which .*cameras.bin does not define"),
    "no frames": (lambda r: write_frames(r, {}, []), "transforms.json", "no frames"),
    "frame without pose": (lambda r: write_frames(r, dict(fl_x=1.0), [dict(file_path="a.png")]),
                           "transforms.json", r"frame 0 \(a.png\): missing 'transform_matrix'"),
    "truncated model": (lambda r: (tiny_colmap(r), _truncate(f"{r}/sparse/0/images.bin")),
                        "sparse/0/images.bin", "truncated"),
    "unreadable json": (lambda r: open(f"{r}/transforms.json", "w").write("{"),
                        "transforms.json", "not valid JSON: .* line 1"),
    "unreadable image": (lambda r: (tiny_colmap(r), _garbage(f"{r}/images/a.png")),
                         "images/a.png", "cannot read the image"),
    "not a dataset": (lambda r: None, "", "not a dataset folder"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_dataset_fails_with_one_message_naming_the_file(tmp_path, case):
    make, file, says = BAD[case]
    make(str(tmp_path))
    with pytest.raises(lgs_jax.DatasetError, match=says) as e:
        lgs_jax.load_dataset(tmp_path)
    message = str(e.value)
    assert message.startswith(os.path.join(str(tmp_path), file) if file else str(tmp_path))
    assert "\n" not in message
    assert isinstance(e.value, ValueError)


def test_distorted_camera_without_opencv_names_the_extra(tmp_path, monkeypatch):
    tiny_transforms(tmp_path, k1=0.01)
    monkeypatch.setitem(sys.modules, "cv2", None)  # import cv2 now raises ImportError
    with pytest.raises(ImportError, match=r"transforms.json: .*pip install 'lgs_jax\[data\]'"):
        lgs_jax.load_dataset(tmp_path)
    tiny_transforms(tmp_path)  # a pinhole camera does not need OpenCV
    assert lgs_jax.load_dataset(tmp_path).images.shape == (1, 30, 40, 3)


# --- the real captures ---------------------------------------------------------------------------

def real(data_dir, name):
    path = os.path.join(data_dir, name)
    if not os.path.isdir(path):
        pytest.skip(f"{name} not found")
    return path


def test_skull_loads_with_its_split_and_points_in_view(data_dir):
    path = real(data_dir, "skull")
    d = lgs_jax.load_dataset(path, downscale=4)
    assert d.names == tuple(f"{i:02d}.jpg" for i in range(1, 67))
    assert len(d.train) == 57 and [d.names[i] for i in d.test] == \
        [f"{i:02d}.jpg" for i in (1, 9, 17, 25, 33, 41, 49, 57, 65)]
    assert d.images.shape == (66, 177, 265, 3) and d.images.dtype == np.float32
    cam = d.cameras[0]  # 1063x708 / 4: the last 3 columns dropped, intrinsics exactly / 4
    assert (cam.width, cam.height, cam.cx, cam.cy) == (265, 177, np.float32(531.5 / 4), 88.5)
    assert cam.fx == cam.fy == np.float32(2402.7815294772545 / 4)
    full = np.asarray(Image.open(os.path.join(path, "images", "01.jpg")), np.float64) / 255
    want = full[:708, :1060].reshape(177, 4, 265, 4, 3).mean((1, 3))
    np.testing.assert_allclose(d.images[0], want, atol=1e-6)
    assert d.points.shape == d.colors.shape == (11582, 3) and d.colors.max() <= 1
    np.testing.assert_array_equal(d.background, [0, 0, 0])
    for cam in d.cameras:  # the SfM points lie on the skull, which every view looks at
        p = d.points @ np.asarray(cam.viewmat)[:3, :3].T + np.asarray(cam.viewmat)[:3, 3]
        u, v = cam.fx * p[:, 0] / p[:, 2] + cam.cx, cam.fy * p[:, 1] / p[:, 2] + cam.cy
        inside = (p[:, 2] > 0) & (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
        assert inside.mean() > 0.95


def bilinear(image, u, v):
    """`image` sampled at pixel-centre coordinates (u, v), the border repeated."""
    x = np.clip(u - 0.5, 0, image.shape[1] - 1)
    y = np.clip(v - 0.5, 0, image.shape[0] - 1)
    x0, y0 = np.minimum(x.astype(int), image.shape[1] - 2), np.minimum(y.astype(int),
                                                                       image.shape[0] - 2)
    a, b = (x - x0)[..., None], (y - y0)[..., None]
    return ((1 - a) * (1 - b) * image[y0, x0] + a * (1 - b) * image[y0, x0 + 1]
            + (1 - a) * b * image[y0 + 1, x0] + a * b * image[y0 + 1, x0 + 1])


def test_fox_is_undistorted_with_its_split(data_dir):
    path = real(data_dir, "fox")
    d = lgs_jax.load_dataset(path, downscale=4)
    meta = json.load(open(os.path.join(path, "transforms.json")))
    assert len(d.names) == 67 and len(d.train) == 58
    assert [d.names[i] for i in d.test] == [f"images/{i:04d}.jpg" for i in
                                            (1, 9, 22, 32, 46, 73, 84, 97, 110)]
    cam = d.cameras[0]
    assert (cam.fx, cam.fy) == (np.float32(meta["fl_x"] / 4), np.float32(meta["fl_y"] / 4))
    assert 530 // 4 <= cam.width < 540 // 4 and 950 // 4 <= cam.height < 960 // 4
    # frame 0 undistorted independently: each pinhole pixel centre through the lens model into
    # the original image, sampled bilinearly, averaged over 4 x 4 blocks
    w, h, fx, fy = 4 * cam.width, 4 * cam.height, 4 * cam.fx, 4 * cam.fy
    xd, yd = distort(*pixel_grid(fx, fy, 4 * cam.cx, 4 * cam.cy, w, h),
                     tuple(meta.get(k, 0.0) for k in ("k1", "k2", "p1", "p2", "k3")))
    u, v = xd * meta["fl_x"] + meta["cx"], yd * meta["fl_y"] + meta["cy"]
    assert u.min() >= 0 and u.max() <= 540 and v.min() >= 0 and v.max() <= 960  # all valid
    src = np.asarray(Image.open(os.path.join(path, "images", "0001.jpg")), np.float64) / 255
    want = bilinear(src, u, v).reshape(cam.height, 4, cam.width, 4, 3).mean((1, 3))
    assert np.abs(d.images[0] - want).max() < 2e-3
    # camera-to-world: the inverse viewmat with its y and z axes negated back to OpenGL
    c2w = np.linalg.inv(np.asarray(cam.viewmat, np.float64))
    c2w[:3, 1:3] *= -1
    np.testing.assert_allclose(c2w, meta["frames"][0]["transform_matrix"], atol=1e-5)
    # load_cameras gives the cameras training uses: undistorted, at full size (the dataset's
    # intrinsics are these divided by 4 exactly, the sizes rounded down)
    cams = lgs_jax.load_cameras(os.path.join(path, "transforms.json"))
    by_name = {os.path.normpath(f["file_path"]): c for f, c in zip(meta["frames"], cams)}
    assert len(by_name) == len(d.names)
    for name, mine in zip(d.names, d.cameras):
        full = by_name[os.path.normpath(name)]
        assert np.asarray(full.viewmat).tobytes() == np.asarray(mine.viewmat).tobytes()
        assert (full.fx / 4, full.fy / 4, full.cx / 4, full.cy / 4) == \
            (mine.fx, mine.fy, mine.cx, mine.cy)
        assert (full.width // 4, full.height // 4) == (mine.width, mine.height)


def test_lego_train_matches_an_independent_reading_with_ids_0_to_90_held_out(data_dir):
    path = real(data_dir, "lego_train")
    d = lgs_jax.load_dataset(path, downscale=2)
    assert [d.names[i] for i in d.test] == [f"train/r_{i}.png" for i in range(0, 100, 10)]
    assert len(d.train) == 90 and d.images.shape == (100, 100, 100, 3)
    np.testing.assert_array_equal(d.background, [1, 1, 1])
    # An independent reading: the transforms.json camera loader and the PNGs composited here.
    import json

    import matplotlib.image

    frames = json.load(open(os.path.join(path, "transforms_train.json")))["frames"]
    cams = lgs_jax.load_cameras(os.path.join(path, "transforms_train.json"))
    rgba = np.stack([matplotlib.image.imread(os.path.join(path, f["file_path"] + ".png"))
                     for f in frames])
    images = rgba[..., :3] * rgba[..., 3:] + (1 - rgba[..., 3:])  # over white, 200x200
    order = [d.names.index(os.path.normpath(f["file_path"]) + ".png") for f in frames]
    want = images.reshape(100, 100, 2, 100, 2, 3).mean((2, 4))
    np.testing.assert_allclose(d.images[order], want, atol=1e-6)
    for c, mine in zip(cams, [d.cameras[i] for i in order]):
        np.testing.assert_array_equal(mine.viewmat, c.viewmat)
        assert (mine.fx, mine.cx, mine.width) == (np.float32(c.fx / 2), np.float32(c.cx / 2), 100)
    centers = np.stack([np.linalg.inv(np.asarray(c.viewmat, np.float64))[:3, 3] for c in cams])
    assert d.extent == pytest.approx(np.linalg.norm(centers - centers.mean(0), axis=1).max())
