"""lgs_jax.viewer: viser's camera states as our cameras (and back), the frame sizes, the frames
themselves, the render loop's coalescing with stand-in clients, and the server answering."""

import contextlib
import dataclasses
import socket
import threading
import time
import types
import urllib.request

import numpy as np
import pytest

import lgs_jax
from lgs_jax import assets as data, viewer
from lgs_jax.cli import main
from lgs_jax.video import render_output, to_uint8


def render_image(scene, cam):
    """The uint8 image of one eager render."""
    return to_uint8(render_output(scene, cam)[0].image)


def test_viewer_pose_and_camera_from_pose_are_inverse():
    for view in range(data.ORBIT_VIEWS):
        cam = lgs_jax.default_camera(view)
        position, wxyz, fov = viewer.viewer_pose(cam)
        back = viewer.camera_from_pose(position, wxyz, fov, cam.width, cam.height)
        np.testing.assert_allclose(np.asarray(back.viewmat), np.asarray(cam.viewmat), atol=1e-6)
        for name in ("fx", "fy", "cx", "cy"):
            np.testing.assert_allclose(float(getattr(back, name)), float(getattr(cam, name)),
                                       rtol=1e-6)


def test_camera_from_pose_follows_visers_opencv_axes():
    """wxyz is the camera-to-world rotation: a quarter turn about world y points the camera's
    +z (forward) along world +x and leaves its y (down) on world y."""
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    cam = viewer.camera_from_pose([1.0, 2.0, 3.0], [c, 0.0, s, 0.0], np.pi / 2, 64, 32)
    view = np.asarray(cam.viewmat, np.float64)
    for world, want in (([6.0, 2.0, 3.0], [0, 0, 5]), ([1.0, 4.0, 3.0], [0, 2, 0])):
        np.testing.assert_allclose(view[:3, :3] @ world + view[:3, 3], want, atol=1e-6)
    assert float(cam.fy) == pytest.approx(16.0)  # 32 / (2 tan 45°)


@pytest.mark.parametrize("aspect,max_size,size", [
    (16 / 9, 1024, (1024, 576)), (9 / 16, 1024, (576, 1024)), (1.0, 100, (96, 96)),
    (50.0, 64, (64, 16)), (1.5, 8, (16, 16)),
])
def test_canvas_sizes_are_whole_tiles_at_the_canvas_aspect(aspect, max_size, size):
    assert viewer.canvas_size(aspect, max_size) == size


@pytest.mark.parametrize("aspect", [0.0, -1.0, float("nan"), float("inf")])
def test_canvas_size_refuses_bad_aspects(aspect):
    with pytest.raises(ValueError, match="aspect"):
        viewer.canvas_size(aspect, 512)


# Every frame of these tests is 64x32 (max size 64 at aspect 2): the programs one test compiles
# (the pair count, the render at a capacity) are the ones the next finds compiled.
SIZE = 64


def test_frames_are_the_render_of_the_pose_and_share_their_program():
    scene = lgs_jax.default_scene()
    renderer = viewer.FrameRenderer(scene)
    position, wxyz, fov = viewer.viewer_pose(lgs_jax.default_camera(0))
    image, _ = renderer.frame(position, wxyz, fov, 2.0, SIZE)
    cam = viewer.camera_from_pose(position, wxyz, fov, 64, 32)
    np.testing.assert_array_equal(image, render_image(scene, cam))
    assert image.shape == (32, 64, 3) and image.max() > 50
    capacity = dict(renderer.capacity)
    renderer.frame(*viewer.viewer_pose(lgs_jax.default_camera(3)), 2.0, SIZE)
    assert renderer.capacity == capacity  # the same size: the same pair buffer


class _Client:
    """A stand-in for viser's ClientHandle: a camera state and the images it was sent."""

    def __init__(self, client_id, view, timestamp=1.0):
        position, wxyz, fov = viewer.viewer_pose(lgs_jax.default_camera(view))
        self.client_id, self.images = client_id, []
        self.camera = types.SimpleNamespace(position=position, wxyz=wxyz, fov=fov, aspect=2.0,
                                            update_timestamp=timestamp)
        self.scene = types.SimpleNamespace(
            set_background_image=lambda image, **_: self.images.append(image))


def test_the_loop_renders_each_clients_latest_camera_once():
    reports = []
    loop = viewer.FrameLoop(viewer.FrameRenderer(lgs_jax.default_scene()), lambda: SIZE,
                            reports.append)
    a, b, silent = _Client(1, 0), _Client(2, 4), _Client(3, 0, timestamp=0.0)
    loop.request(a)
    a.camera.position, a.camera.wxyz, _ = viewer.viewer_pose(lgs_jax.default_camera(2))
    for client in (a, b, silent, a):
        loop.request(client)
    worker = threading.Thread(target=loop.run)
    worker.start()
    deadline = time.time() + 120
    while len(a.images) + len(b.images) < 2 and time.time() < deadline:
        time.sleep(0.05)
    loop.stop()
    worker.join()
    assert (len(a.images), len(b.images), len(silent.images)) == (1, 1, 0)
    want = viewer.FrameRenderer(lgs_jax.default_scene()).frame(
        *viewer.viewer_pose(lgs_jax.default_camera(2)), 2.0, SIZE)[0]
    np.testing.assert_array_equal(a.images[0], want)  # the latest pose, not the first
    assert reports and reports[0].startswith("64x32, ")


def test_a_failed_render_is_reported_and_the_loop_goes_on():
    reports = []
    loop = viewer.FrameLoop(viewer.FrameRenderer(lgs_jax.default_scene()), lambda: SIZE,
                            reports.append)
    bad = _Client(1, 0)
    bad.camera.aspect = float("nan")
    loop.render(bad)
    assert reports == ["render failed: ValueError: aspect: expected a finite number > 0, "
                       "got nan"] and not bad.images


def test_the_server_serves_the_page():
    pytest.importorskip("viser")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    served = viewer.serve(lgs_jax.default_scene(), [lgs_jax.default_camera()],
                          host="127.0.0.1", port=port, block=False)
    try:
        page = urllib.request.urlopen(f"http://127.0.0.1:{served.port}/", timeout=30).read()
        assert b"<html" in page
    finally:
        served.stop()


def _run_until(loop, done):
    """Run `loop` in a thread until `done()` (at most two minutes), then stop it."""
    worker = threading.Thread(target=loop.run)
    worker.start()
    deadline = time.time() + 120
    while not done() and time.time() < deadline:
        time.sleep(0.05)
    loop.stop()
    worker.join()


def test_a_shown_scene_is_rendered_for_every_client():
    """No scene: nothing is rendered or reported. `Served.show` swaps the scene in, sets the
    status and renders every connected client's view of the new scene."""
    reports, status = [], types.SimpleNamespace(content="")
    loop = viewer.FrameLoop(viewer.FrameRenderer(None), lambda: SIZE, reports.append)
    a, b = _Client(1, 0), _Client(2, 5)
    loop.render(a)
    assert not a.images and not reports
    server = types.SimpleNamespace(get_clients=lambda: {1: a, 2: b})
    served = viewer.Served(8080, loop, server, status, loop.stop)
    scene = lgs_jax.default_scene()
    served.show(scene, "step 3")
    _run_until(loop, lambda: a.images and b.images)
    assert status.content == "step 3" and len(a.images) == len(b.images) == 1
    want = viewer.FrameRenderer(scene).frame(*viewer.viewer_pose(lgs_jax.default_camera(5)),
                                             2.0, SIZE)[0]
    np.testing.assert_array_equal(b.images[0], want)


def test_a_growing_scene_grows_the_pair_buffer_with_headroom():
    """A scene whose views come to need more pairs (as in training) is rendered in a buffer
    grown to `headroom` times them. The scene grows by enlarging its Gaussians (log-scales
    + 1.3: 8802 pairs, more than the default scene's buffer holds), so that both scenes have one
    shape: the first frame is the default scene's, the program the other tests compiled, and
    the grown buffer's is the one new program."""
    scene = lgs_jax.default_scene()
    grown = dataclasses.replace(scene, log_scales=(scene.log_scales + 1.3).astype(
        scene.log_scales.dtype))
    renderer = viewer.FrameRenderer(scene, headroom=2.0)
    state = viewer.viewer_pose(lgs_jax.default_camera(0))
    renderer.frame(*state, 2.0, SIZE)
    first = renderer.capacity[64, 32]
    renderer.scene = grown
    image, _ = renderer.frame(*state, 2.0, SIZE)
    # the scene's render in the grown buffer, which holds its pairs (nothing dropped)
    out, _ = render_output(grown, viewer.camera_from_pose(*state, 64, 32),
                           renderer.capacity[64, 32])
    pairs = int(out.stats.pairs_required)
    assert pairs > first and renderer.capacity[64, 32] == lgs_jax.pair_capacity(pairs, 2.0)
    assert not bool(out.stats.overflow)
    np.testing.assert_array_equal(image, to_uint8(out.image))


def test_a_viewer_without_a_scene_looks_where_the_cameras_look():
    cams = [lgs_jax.default_camera(v) for v in range(4)]
    target = viewer.look_target(cams, None)
    centre, rot = viewer.poses.pose(cams[0])
    np.testing.assert_allclose(target, centre + rot[2] * (rot[2] @ (
        viewer.poses.axes_centre(cams) - centre)), atol=1e-9)
    np.testing.assert_allclose(viewer.look_target(cams[:1], None), centre + rot[2])


@pytest.mark.parametrize("args,match", [
    (["--view", "8"], "--view: 8 is out of range: the default scene has 8 orbit views"),
    (["{ply}"], "--cameras: needed to view a scene file"),
    (["--max-size", "8"], "--max-size: must be >= 16"),
])
def test_view_command_line_errors(tmp_path, capsys, args, match):
    ply = tmp_path / "s.ply"
    lgs_jax.save_ply(ply, lgs_jax.default_scene())
    try:
        code = main(["view", *[a.format(ply=ply) for a in args]])
    except SystemExit as e:
        code = e.code
    assert code == 2
    assert match in capsys.readouterr().err


class _Frustum:
    def __init__(self, **kwargs):
        self.kwargs, self.clicks = kwargs, []

    def on_click(self, fn):
        self.clicks.append(fn)


def test_cameras_are_drawn_and_a_click_moves_the_view_there():
    cams = [lgs_jax.default_camera(v) for v in range(3)]
    drawn = []
    scene_api = types.SimpleNamespace(
        add_camera_frustum=lambda name, **kw: drawn.append(_Frustum(name=name, **kw)) or drawn[-1])
    viewer.add_cameras(scene_api, cams, viewer.frustum_scale(cams))
    assert [f.kwargs["name"] for f in drawn] == ["/cameras/0", "/cameras/1", "/cameras/2"]
    centres = np.stack([viewer.poses.pose(c)[0] for c in cams])
    spread = np.linalg.norm(centres - centres.mean(0), axis=1).max()
    assert drawn[0].kwargs["scale"] == pytest.approx(0.05 * spread)
    client = types.SimpleNamespace(camera=types.SimpleNamespace(), atomic=contextlib.nullcontext)
    drawn[2].clicks[0](types.SimpleNamespace(client=client))
    position, wxyz, fov = viewer.viewer_pose(cams[2])
    back = viewer.camera_from_pose(client.camera.position, client.camera.wxyz, client.camera.fov,
                                   cams[2].width, cams[2].height)
    np.testing.assert_allclose(np.asarray(back.viewmat), np.asarray(cams[2].viewmat), atol=1e-6)
    assert drawn[2].kwargs["fov"] == fov and drawn[2].kwargs["aspect"] == 1280 / 720


def test_the_view_command_draws_the_capture_or_the_orbit_and_starts_at_view(
        monkeypatch):
    served = []
    monkeypatch.setattr(viewer, "serve", lambda scene, cams, start, **_: served.append(
        ([np.asarray(c.viewmat) for c in cams], start)))
    assert main(["view"]) == 0 and main(["view", "--view", "5"]) == 0
    framing, orbit = lgs_jax.default_camera(), [lgs_jax.default_camera(v) for v in range(8)]
    (first, start_a), (second, start_b) = served
    assert len(first) == 9 and start_a == 0
    np.testing.assert_array_equal(first[0], np.asarray(framing.viewmat))
    assert len(second) == 8 and start_b == 5
    np.testing.assert_array_equal(second[5], np.asarray(orbit[5].viewmat))
