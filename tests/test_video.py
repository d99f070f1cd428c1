"""lgs_jax.video and `python -m lgs_jax video`: the orbit fitted to a capture's cameras, the path
through them, the frames' encoding (decoded again with imageio-ffmpeg), and the command line's
checks."""

import os
import warnings

import imageio_ffmpeg
import numpy as np
import pytest

import lgs_jax
from lgs_jax import assets as data, poses, video
from lgs_jax.cli import main


def _orbit_cameras(width=320, height=180):
    return [lgs_jax.default_camera(v, width, height) for v in range(data.ORBIT_VIEWS)]


def _decode(path):
    reader = imageio_ffmpeg.read_frames(str(path))
    with warnings.catch_warnings():  # ffmpeg is exec'd at once: JAX's fork warning is moot
        warnings.filterwarnings("ignore", "os.fork", RuntimeWarning)
        meta = next(reader)
    w, h = meta["size"]
    return [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader]


def test_orbit_through_the_default_scenes_orbit_cameras_is_those_cameras():
    """The bundled scene's 8 cameras lie on a circle looking at one point, so the fit (centre
    nearest their axes, mean up, mean height and radius) gives them back, in order."""
    cams = _orbit_cameras()
    for cam, fitted in zip(cams, video.orbit_path(cams, len(cams))):
        np.testing.assert_allclose(np.asarray(fitted.viewmat), np.asarray(cam.viewmat),
                                   atol=1e-6)
        assert (fitted.width, fitted.height, fitted.fx) == (cam.width, cam.height, cam.fx)


def test_orbit_frames_look_at_the_centre_from_equal_distance():
    path = video.orbit_path(_orbit_cameras(), 13, turns=-0.5)
    centres = np.stack([poses.pose(c)[0] for c in path])
    forward = np.stack([poses.pose(c)[1][2] for c in path])
    # every optical axis passes through one point: the axes' nearest point lies on all of them
    off = np.eye(3) - forward[:, :, None] * forward[:, None, :]
    point = np.linalg.solve(off.sum(0), np.einsum("nij,nj->i", off, centres))
    distance = np.linalg.norm(centres - point, axis=1)
    np.testing.assert_allclose(distance, distance[0], rtol=1e-5)
    assert np.abs(np.einsum("nij,nj->ni", off, point - centres)).max() < 1e-5 * distance[0]


@pytest.mark.parametrize("make,match", [
    (lambda cams: cams[:1], "at least 2 cameras"),
    (lambda cams: [cams[0], poses.posed(cams[0], poses.pose(cams[0])[0] + [1.0, 0, 0],
                                      poses.pose(cams[0])[1])], "parallel"),
])
def test_orbit_refuses_cameras_it_cannot_fit(make, match):
    with pytest.raises(ValueError, match=match):
        video.orbit_path(make(_orbit_cameras()), 4)


@pytest.mark.parametrize("frames", [0, -1, 2.5, True])
def test_frame_counts_are_checked(frames):
    with pytest.raises(ValueError, match="frames: expected an int >= 1"):
        video.camera_path(_orbit_cameras(), frames)


def test_camera_path_starts_and_ends_at_the_cameras_and_interpolates_between():
    cams = _orbit_cameras()[:3]
    path = video.camera_path(cams, 5)  # cameras at steps 0, 2, 4
    for i, k in ((0, 0), (1, 2), (2, 4)):
        np.testing.assert_allclose(np.asarray(path[k].viewmat), np.asarray(cams[i].viewmat),
                                   atol=1e-6)
    (o0, r0), (o1, r1) = poses.pose(cams[0]), poses.pose(cams[1])
    mid, rot = poses.pose(path[1])
    np.testing.assert_allclose(mid, (o0 + o1) / 2, atol=1e-6)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-6)
    np.testing.assert_allclose(rot @ r0.T, r1 @ rot.T, atol=1e-6)  # the geodesic's midpoint
    third = poses.pose(video.camera_path(cams[:2], 4)[1])[1] @ r0.T  # a third of the way
    np.testing.assert_allclose(third @ third @ third, r1 @ r0.T, atol=1e-5)  # equal steps
    assert len(video.camera_path(cams[:1], 3)) == 3


def test_look_at_puts_the_target_ahead_and_up_up():
    rot = poses.look_at([0.0, 0.0, 0.0], [0.0, 0.0, 5.0], [0.0, -1.0, 0.0])
    np.testing.assert_allclose(rot, np.eye(3), atol=1e-12)  # OpenCV: y down, so up is −y
    with pytest.raises(ValueError, match="parallel"):
        poses.look_at([0, 0, 0], [0, 1, 0], [0, 1, 0])


def test_written_video_decodes_to_the_frames(tmp_path):
    y, x = np.mgrid[0:48, 0:64]
    frames = [np.stack([(x * 4 + k * 16) % 256, y * 5, np.full_like(x, 128)], -1)
              .astype(np.uint8) for k in range(4)]
    out = tmp_path / "v.mp4"
    assert video.write_video(str(out), iter(frames), fps=10) == 4
    decoded = _decode(out)
    assert len(decoded) == 4
    for a, b in zip(frames, decoded):
        mse = np.mean((a.astype(float) - b) ** 2)
        assert 10 * np.log10(255 ** 2 / mse) > 30


@pytest.mark.parametrize("stop", [KeyboardInterrupt, RuntimeError])
def test_an_interrupted_video_leaves_no_file(tmp_path, stop):
    """Ctrl-C (or a failure) after two frames: no shorter video under the name asked for, an
    older one there kept, no temporary left."""
    def frames():
        for k in range(4):
            if k == 2:
                raise stop("stopped")
            yield np.full((8, 8, 3), 40 * k, np.uint8)

    with pytest.raises(stop):
        video.write_video(str(tmp_path / "v.mp4"), frames())
    assert os.listdir(tmp_path) == []
    (tmp_path / "old.mp4").write_bytes(b"an older video")
    with pytest.raises(stop):
        video.write_video(str(tmp_path / "old.mp4"), frames())
    assert os.listdir(tmp_path) == ["old.mp4"]
    assert (tmp_path / "old.mp4").read_bytes() == b"an older video"


@pytest.mark.parametrize("frames,match", [
    ([np.zeros((9, 8, 3), np.uint8)], "even width and height, got 8x9"),
    ([np.zeros((8, 8, 3), np.float32)], r"expected \(height, width, 3\) uint8"),
    ([np.zeros((8, 8, 3), np.uint8), np.zeros((8, 10, 3), np.uint8)], "frame 1 is"),
])
def test_bad_frames_are_refused(tmp_path, frames, match):
    with pytest.raises(ValueError, match=match):
        video.write_video(str(tmp_path / "v.mp4"), frames)


def test_video_command_writes_an_orbit_of_the_default_scene(tmp_path, capsys):
    out = tmp_path / "orbit.mp4"
    assert main(["video", "--frames", "3", "--width", "64", "--out", str(out)]) == 0
    assert "3 frames 64x36" in capsys.readouterr().out
    frames = _decode(out)
    assert len(frames) == 3 and frames[0].shape == (36, 64, 3)
    assert frames[0].max() > 50  # the label is in view, not an empty frame
    depth = tmp_path / "depth.mp4"  # the depth's turbo colours: blue and red, not grey
    assert main(["video", "--frames", "2", "--width", "64", "--output", "depth", "--out",
                 str(depth)]) == 0
    first = _decode(depth)[0].astype(int)
    assert np.abs(first[..., 2] - first[..., 0]).max() > 100


@pytest.mark.parametrize("args,match", [
    (["--width", "97"], "--width/--height: H.264 needs an even width and height, got 97x55"),
    (["--out", "v.gif"], "extension '.gif' is not a video format written here; use .mp4"),
    (["--fps", "0"], "--fps: must be >= 1"),
    (["{ply}"], "--cameras: needed for a video of a scene file"),
])
def test_video_command_line_errors(tmp_path, capsys, args, match):
    ply = tmp_path / "s.ply"
    lgs_jax.save_ply(ply, lgs_jax.default_scene())
    argv = ["video", *[a.format(ply=ply) for a in args]]
    if "--out" not in args:
        argv += ["--out", str(tmp_path / "v.mp4")]
    try:
        code = main(argv)
    except SystemExit as e:
        code = e.code
    assert code == 2
    assert match in capsys.readouterr().err


def test_orbit_of_a_real_capture_circles_its_points(data_dir):
    """Skull (COLMAP, 66 cameras of a hand-held capture): the fitted orbit's centre, where its
    frames' optical axes meet, lies at the SfM points' median (within 10% of the radius)."""
    path = os.path.join(data_dir, "skull")
    if not os.path.isdir(path):
        pytest.skip("skull not found")
    d = lgs_jax.load_dataset(path, downscale=32)
    orbit = video.orbit_path(list(d.cameras), 12)
    centres = np.stack([poses.pose(c)[0] for c in orbit])
    forward = np.stack([poses.pose(c)[1][2] for c in orbit])
    off = np.eye(3) - forward[:, :, None] * forward[:, None, :]
    point = np.linalg.solve(off.sum(0), np.einsum("nij,nj->i", off, centres))
    radius = np.linalg.norm(centres - point, axis=1).mean()
    assert np.linalg.norm(point - np.median(d.points, 0)) < 0.1 * radius


def test_frames_show_the_image_the_alpha_or_the_expected_depth():
    out = lgs_jax.render(lgs_jax.default_scene(), lgs_jax.default_camera(0, 64, 36))
    image, alpha, depth = (video.frame_pixels(out, o) for o in ("image", "alpha", "depth"))
    np.testing.assert_array_equal(image, video.to_uint8(out.image))
    a = np.asarray(out.alpha)
    np.testing.assert_array_equal(alpha[..., 0], np.round(np.clip(a, 0, 1) * 255))
    assert (alpha[..., 0] == alpha[..., 2]).all()
    seen = a >= 0.05
    assert seen.any() and (~seen).any()
    assert (depth[~seen] == 0).all() and depth[seen].max() > 0
    z = np.asarray(out.depth) / np.where(seen, a, 1)  # turbo: blue (near) to red (far)
    near = np.unravel_index(np.argmin(np.where(seen, z, np.inf)), a.shape)
    far = np.unravel_index(np.argmax(np.where(seen, z, -np.inf)), a.shape)
    assert depth[near][2] > depth[near][0] and depth[far][0] > depth[far][2]
    with pytest.raises(ValueError, match="output: expected one of"):
        video.frame_pixels(out, "normals")


def test_depth_videos_keep_the_first_frames_colour_range():
    scene = lgs_jax.default_scene()
    cams = [lgs_jax.default_camera(v, 64, 36) for v in (0, 4)]
    frames = list(video.render_frames(scene, cams, "depth"))
    outs = [video.render_output(scene, c)[0] for c in cams]
    span = video.depth_range(outs[0])
    assert span != video.depth_range(outs[1])
    for frame, out in zip(frames, outs):
        np.testing.assert_array_equal(frame, video.frame_pixels(out, "depth", span))
