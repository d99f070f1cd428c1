"""Captures that are wrong: invalid intrinsics, poses and points, oversized header counts, 16-bit
images and a downscale larger than the images. Each is refused with one `DatasetError` naming
the file, the frame, image or point and the field; nothing loads as if it were fine."""

import math
import os
import re
import struct

import numpy as np
import pytest
from PIL import Image

import lgs_jax
from lgs_jax.io.datasets import as_float
from tests.io.captures import tiny_colmap, tiny_transforms, write_frames

NAN, INF = float("nan"), float("inf")


def _scaled(s):
    m = np.eye(4)
    m[:3, :3] *= s
    return m.tolist()


def _sheared():
    m = np.eye(4)
    m[0, 1] = 0.3
    return m.tolist()


def _frame_with(**fields):
    """A transforms.json whose one frame carries `fields` (overriding the shared fl_x=40)."""
    frame = dict(file_path="images/a.png", transform_matrix=np.eye(4).tolist())
    return lambda r: write_frames(r, dict(fl_x=40.0), [dict(frame, **fields)])


TRANSFORMS = {  # case: (make the capture, what the message says after "frame 0 (images/a.png): ")
    "fl_x 0": (lambda r: tiny_transforms(r, fl_x=0.0), "fl_x must be a finite number > 0, got 0.0"),
    "fl_x negative": (lambda r: tiny_transforms(r, fl_x=-300), "fl_x must be a finite number > 0"),
    "fl_x nan": (lambda r: tiny_transforms(r, fl_x=NAN), "fl_x must be a finite number > 0"),
    "fl_x text": (lambda r: tiny_transforms(r, fl_x="40"), "fl_x must be a finite number > 0"),
    "fl_y 0 in the frame": (_frame_with(fl_y=0), "fl_y must be a finite number > 0"),
    "angle pi": (lambda r: tiny_transforms(r, fl_x=None, camera_angle_x=math.pi),
                 r"camera_angle_x must be a field of view in radians, 0 < a < π, got 3.14"),
    "angle 0": (lambda r: tiny_transforms(r, fl_x=None, camera_angle_x=0.0),
                "camera_angle_x must be a field of view"),
    "angle negative": (lambda r: tiny_transforms(r, fl_x=None, camera_angle_x=-0.5),
                       "camera_angle_x must be a field of view"),
    "angle nan": (lambda r: tiny_transforms(r, fl_x=None, camera_angle_x=NAN),
                  "camera_angle_x must be a field of view"),
    "angle_y pi": (lambda r: tiny_transforms(r, camera_angle_y=4.0),
                   "camera_angle_y must be a field of view"),
    "cx inf": (lambda r: tiny_transforms(r, cx=INF), "cx must be a finite number"),
    "k1 nan": (lambda r: tiny_transforms(r, k1=NAN), "k1 must be a finite number"),
    "w 0": (lambda r: tiny_transforms(r, w=0, h=30), "w must be a positive whole number"),
    "scaled rotation": (_frame_with(transform_matrix=_scaled(2.0)),
                        "transform_matrix: rotation is not orthonormal"),
    "sheared rotation": (_frame_with(transform_matrix=_sheared()),
                         "transform_matrix: rotation is not orthonormal"),
    "reflection": (_frame_with(transform_matrix=np.diag([-1.0, 1, 1, 1]).tolist()),
                   "transform_matrix: rotation is a reflection"),
    "inf entry": (_frame_with(transform_matrix=np.where(np.eye(4), 1, INF).tolist()),
                  "transform_matrix must be 4x4 finite numbers"),
    "bad last row": (_frame_with(transform_matrix=np.ones((4, 4)).tolist()),
                     "transform_matrix"),
}


@pytest.mark.parametrize("case", TRANSFORMS)
def test_invalid_transforms_intrinsics_and_poses_name_file_frame_and_field(tmp_path, case):
    make, says = TRANSFORMS[case]
    path = make(str(tmp_path))
    with pytest.raises(lgs_jax.DatasetError) as e:
        lgs_jax.load_dataset(tmp_path)
    message = str(e.value)
    assert message.startswith(f"{path}: frame 0 (images/a.png): "), message
    assert re.search(says, message), message
    assert "\n" not in message
    # the cameras reader reads transforms.json with the same parser
    with pytest.raises(lgs_jax.DatasetError, match=says):
        lgs_jax.load_cameras(path)


SIMPLE, PINHOLE = 0, 1
COLMAP = {  # case: (tiny_colmap arguments, file, what the message says)
    "f 0": (dict(model=(SIMPLE, (0.0, 4.0, 3.0))), "cameras",
            r"camera 1 \(SIMPLE_PINHOLE\): f must be a finite number > 0, got 0.0"),
    "f negative": (dict(model=(SIMPLE, (-80.0, 4.0, 3.0))), "cameras",
                   r"camera 1 \(SIMPLE_PINHOLE\): f must be a finite number > 0, got -80.0"),
    "fy nan": (dict(model=(PINHOLE, (8.0, NAN, 4.0, 3.0))), "cameras",
               r"camera 1 \(PINHOLE\): fy must be a finite number > 0, got nan"),
    "cx inf": (dict(model=(PINHOLE, (8.0, 8.0, INF, 3.0))), "cameras",
               r"camera 1 \(PINHOLE\): cx must be a finite number, got inf"),
    "k1 nan": (dict(model=(2, (8.0, 4.0, 3.0, NAN))), "cameras",
               r"camera 1 \(SIMPLE_RADIAL\): k1 must be a finite number, got nan"),
    "zero quaternion": (dict(poses={"b.png": ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0))}),
                        "images", r"image 'b.png' \(id 2\): qvec \(0.0, 0.0, 0.0, 0.0\) is not a "
                                  "rotation"),
    "nan quaternion": (dict(poses={"a.png": ((NAN, 0.0, 0.0, 1.0), (0.0, 0.0, 1.0))}),
                       "images", r"image 'a.png' \(id 1\): qvec \(nan, 0.0, 0.0, 1.0\) is not a "
                                 "rotation"),
    "inf translation": (dict(poses={"a.png": ((1.0, 0.0, 0.0, 0.0), (0.0, INF, 1.0))}),
                        "images", r"image 'a.png' \(id 1\): tvec \(0.0, inf, 1.0\) must be finite"),
    "nan point": (dict(point=(0.0, NAN, 1.0)), "points3D",
                  r"point 1: position \(0.0, nan, 1.0\) is not finite"),
    "inf point": (dict(point=(INF, 0.0, 1.0)), "points3D",
                  r"point 1: position \(inf, 0.0, 1.0\) is not finite"),
}


@pytest.mark.parametrize("fmt", ["bin", "txt"])
@pytest.mark.parametrize("case", COLMAP)
def test_invalid_colmap_cameras_poses_and_points_name_file_record_and_field(tmp_path, case, fmt):
    kwargs, file, says = COLMAP[case]
    tiny_colmap(str(tmp_path), fmt=fmt, **kwargs)
    with pytest.raises(lgs_jax.DatasetError) as e:
        lgs_jax.load_dataset(tmp_path)
    message = str(e.value)
    assert message.startswith(os.path.join(str(tmp_path), "sparse", "0", f"{file}.{fmt}: "))
    assert re.search(says, message), message


@pytest.mark.parametrize("file", ["cameras", "images", "points3D"])
def test_binary_header_counts_beyond_the_file_size_are_refused_before_allocating(tmp_path, file):
    tiny_colmap(str(tmp_path))
    path = os.path.join(str(tmp_path), "sparse", "0", f"{file}.bin")
    data = open(path, "rb").read()
    open(path, "wb").write(struct.pack("<Q", 2**40) + data[8:])
    with pytest.raises(lgs_jax.DatasetError, match=rf"{file}.bin: declares 1099511627776 "
                                                   r"\w+, which need at least \d+ bytes; the file"
                                                   r" has \d+ after its count"):
        lgs_jax.load_dataset(tmp_path)


# --- images ---------------------------------------------------------------------------------------

def _png16(path, pixels):
    """Write a 16-bit PNG (grey (H, W) or colour (H, W, 3|4) uint16, RGB order) with OpenCV."""
    cv2 = pytest.importorskip("cv2")
    if pixels.ndim == 3:
        pixels = pixels[..., [2, 1, 0, 3][:pixels.shape[2]]]  # OpenCV writes BGR(A)
    assert cv2.imwrite(str(path), pixels)


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_16_bit_png_is_read_at_its_bit_depth(tmp_path, channels):
    rng = np.random.default_rng(3)
    shape = (30, 40) if channels == 1 else (30, 40, channels)
    pixels = rng.integers(0, 65536, shape, dtype=np.uint16)
    pixels.flat[:3] = (0, 257, 65535)
    if channels == 4:
        pixels[..., 3] = 65535  # opaque: compositing leaves the colour as it is
    tiny_transforms(str(tmp_path))
    _png16(tmp_path / "images" / "a.png", pixels)
    d = lgs_jax.load_dataset(tmp_path)
    rgb = np.repeat(pixels[..., None], 3, -1) if channels == 1 else pixels[..., :3]
    want = rgb.astype(np.float32) / np.float32(65535)
    np.testing.assert_array_equal(d.images[0], want)


def test_16_bit_png_with_alpha_is_composited_at_16_bits(tmp_path):
    pixels = np.zeros((30, 40, 4), np.uint16)
    pixels[..., 0], pixels[..., 3] = 65535, 32768  # red, half transparent over black
    tiny_transforms(str(tmp_path))
    _png16(tmp_path / "images" / "a.png", pixels)
    d = lgs_jax.load_dataset(tmp_path)
    assert d.images[0, 0, 0, 0] == np.float32(32768 / 65535)


def test_8_bit_png_keeps_its_exact_bits(tmp_path):
    rng = np.random.default_rng(4)
    pixels = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    tiny_transforms(str(tmp_path))
    Image.fromarray(pixels).save(tmp_path / "images" / "a.png")
    d = lgs_jax.load_dataset(tmp_path)
    np.testing.assert_array_equal(d.images[0], pixels.astype(np.float32) / np.float32(255))


@pytest.mark.parametrize("bits", [8, 16])
def test_auto_dtype_holds_8_bit_files_as_uint8_and_16_bit_ones_as_float32(tmp_path, bits):
    rng = np.random.default_rng(5)
    tiny_transforms(str(tmp_path))
    if bits == 8:
        pixels = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
        Image.fromarray(pixels).save(tmp_path / "images" / "a.png")
    else:
        pixels = rng.integers(0, 65536, (30, 40, 3), dtype=np.uint16)
        _png16(tmp_path / "images" / "a.png", pixels)
    auto = lgs_jax.load_dataset(tmp_path, dtype="auto")
    assert auto.images.dtype == (np.uint8 if bits == 8 else np.float32)
    exact = lgs_jax.load_dataset(tmp_path)
    np.testing.assert_array_equal(as_float(auto.images), exact.images)


def test_downscale_larger_than_the_images_is_refused(tmp_path):
    tiny_transforms(str(tmp_path))  # 40x30 images
    assert lgs_jax.load_dataset(tmp_path, downscale=30).images.shape == (1, 1, 1, 3)
    with pytest.raises(lgs_jax.DatasetError, match=r"images/a.png: downscale 31 is larger than "
                                                   r"the image \(40x30 pixels\)"):
        lgs_jax.load_dataset(tmp_path, downscale=31)
