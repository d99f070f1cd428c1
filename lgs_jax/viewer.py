"""A browser viewer: `serve(scene, cameras)` starts a viser server (http://localhost:8080 by
default) in which the mouse orbits, pans and zooms; every camera change renders that view with
`lgs_jax.render` and shows it as the page's background image.

    lgs_jax.viewer.serve(lgs_jax.load_ply("scene.ply"), lgs_jax.load_cameras("cameras.json"))

Frames are the client canvas's aspect ratio with the longer side `max_size` pixels (a slider
sets it), both sides whole 16-pixel tiles (`canvas_size`), so only a new aspect ratio or size
compiles again; the pair buffer is carried from frame to frame (`video.render_output`). One
thread renders; each client's latest camera wins and older poses are dropped, never queued.
A dropdown picks what a frame shows: the image, the expected depth (colour-mapped) or the
alpha (`frame_pixels`). The cameras are drawn as frusta; a click on one moves the view there.

Cameras: viser's follow OpenCV axes as ours do (x right, y down, z forward); its `wxyz` is the
camera-to-world rotation R and `position` the camera centre c, so viewmat = [Rᵀ | −Rᵀc], and its
`fov` the vertical field of view: fy = fx = height / (2 tan(fov / 2)), the principal point at
the image centre (`camera_from_pose`, `viewer_pose`). viser is optional: `pip install
"lgs_jax[viewer]"`.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from . import poses
from .layout import TILE
from .scene import Camera
from .video import OUTPUTS, frame_pixels, render_output


def camera_from_pose(position, wxyz, fov_y: float, width: int, height: int) -> Camera:
    """The `Camera` of a viser camera state: centre `position`, camera-to-world rotation `wxyz`
    (w, x, y, z), vertical field of view `fov_y` (radians), an image of width x height."""
    focal = 0.5 * height / math.tan(0.5 * fov_y)
    cam = Camera(viewmat=np.eye(4, dtype=np.float32), fx=np.float32(focal),
                 fy=np.float32(focal), cx=np.float32(width / 2), cy=np.float32(height / 2),
                 width=int(width), height=int(height))
    rot = poses.rotation(np.asarray(wxyz, np.float64) / np.linalg.norm(wxyz)).T
    return poses.posed(cam, np.asarray(position, np.float64), rot)


def viewer_pose(cam: Camera) -> tuple[np.ndarray, np.ndarray, float]:
    """(position, wxyz, fov_y) of `cam` for viser (`camera_from_pose`'s inverse, the field of
    view from fy)."""
    centre, rot = poses.pose(cam)
    return centre, poses.quaternion(rot.T), 2 * math.atan(0.5 * cam.height / float(cam.fy))


def canvas_size(aspect: float, max_size: int) -> tuple[int, int]:
    """(width, height) of a frame for a canvas of width / height `aspect`: the longer side
    `max_size` rounded to whole tiles, the other side in proportion, rounded to whole tiles,
    at least one tile."""
    if not (math.isfinite(aspect) and aspect > 0):
        raise ValueError(f"aspect: expected a finite number > 0, got {aspect!r}")
    longer = max(TILE, round(max_size / TILE) * TILE)
    shorter = lambda r: max(TILE, round(longer * r / TILE) * TILE)
    return (longer, shorter(1 / aspect)) if aspect >= 1 else (shorter(aspect), longer)


class FrameRenderer:
    """The viewer's rendering without its server: a viser camera state to a uint8 frame
    (`frame_pixels`), the pair buffer carried per image size (`video.render_output`, grown to
    `headroom` times a view's pairs). `scene` may be replaced between frames (a scene in
    training), or None (nothing to show yet)."""

    def __init__(self, scene, headroom: float = 1.0, **render_kwargs):
        self.scene, self.headroom, self.render_kwargs = scene, headroom, render_kwargs
        self.capacity: dict[tuple[int, int], int] = {}

    def frame(self, position, wxyz, fov_y: float, aspect: float, max_size: int,
              output: str = "image"):
        """(frame, seconds) of the view at this camera state and size."""
        width, height = canvas_size(aspect, max_size)
        cam = camera_from_pose(position, wxyz, fov_y, width, height)
        t0 = time.perf_counter()
        out, self.capacity[width, height] = render_output(
            self.scene, cam, self.capacity.get((width, height)), self.headroom,
            **self.render_kwargs)
        return frame_pixels(out, output), time.perf_counter() - t0


def _initial_view(server, cam: Camera, target) -> None:
    """New clients start at `cam`, looking at `target` (its up the camera's −y)."""
    centre, rot = poses.pose(cam)
    up = -rot[1]
    server.initial_camera.position = tuple(centre)
    server.initial_camera.look_at = tuple(np.asarray(target, np.float64))
    server.initial_camera.up = tuple(up)
    server.initial_camera.fov = viewer_pose(cam)[2]
    server.scene.set_up_direction(tuple(up))


def look_target(cameras, scene) -> np.ndarray:
    """The point the first camera orbits: along its axis, as deep as the opacity-weighted
    centre of the scene's finite means, or without a scene the point nearest the cameras'
    axes (`poses.axes_centre`; one unit ahead where they do not meet), at least 1e-3 ahead."""
    centre, rot = poses.pose(cameras[0])
    mid = centre + rot[2]
    if scene is not None:
        means = np.asarray(scene.means, np.float64)
        weight = 1 / (1 + np.exp(-np.asarray(scene.logit_opacities, np.float64)))
        ok = np.all(np.isfinite(means), -1) & np.isfinite(weight)
        if ok.any():
            mid = weight[ok] @ means[ok] / max(weight[ok].sum(), 1e-30)
    elif len(cameras) > 1:
        try:
            mid = poses.axes_centre(cameras)
        except ValueError:  # parallel axes: keep one unit ahead
            pass
    return centre + rot[2] * max(float(rot[2] @ (mid - centre)), 1e-3)


def frustum_scale(cameras) -> float:
    """A drawn camera's depth: 5% of the cameras' spread (their largest distance from their
    mean centre), or 0.1 for one camera or cameras in one place."""
    centres = np.stack([poses.pose(c)[0] for c in cameras])
    spread = float(np.linalg.norm(centres - centres.mean(0), axis=1).max())
    return 0.05 * spread if spread > 0 else 0.1


def add_cameras(scene_api, cameras, scale: float):
    """Draw each camera as a frustum (viser's `scene` API); clicking one moves the clicking
    browser's view to that camera (position, rotation, field of view). Returns the handles."""
    handles = []
    for i, cam in enumerate(cameras):
        position, wxyz, fov = viewer_pose(cam)
        handle = scene_api.add_camera_frustum(
            f"/cameras/{i}", fov=fov, aspect=cam.width / cam.height, scale=scale,
            thickness=1.5, thickness_units="screen",  # not a wall across a view through it
            wxyz=tuple(wxyz), position=tuple(position), color=(80, 120, 255))

        def go(event, position=position, wxyz=wxyz, fov=fov) -> None:
            with event.client.atomic():
                event.client.camera.wxyz = tuple(wxyz)
                event.client.camera.position = tuple(position)
                event.client.camera.fov = fov

        handle.on_click(go)
        handles.append(handle)
    return handles


class FrameLoop:
    """The viewer's render thread: `request(client)` marks a client's view as changed; `run()`
    renders each marked client's *latest* camera state in turn (a client marked again before
    its turn is rendered once) and sends it as the client's background image; `report(text)`
    gets each frame's size and time, or a failure (the loop goes on). `max_size()` and
    `output()` (one of `OUTPUTS`) are read per frame. Clients are viser `ClientHandle`s, or
    anything with `client_id`, `camera` (position, wxyz, fov, aspect, update_timestamp) and
    `scene.set_background_image`."""

    def __init__(self, renderer: FrameRenderer, max_size, report, output=lambda: "image"):
        self.renderer, self.max_size, self.report = renderer, max_size, report
        self.output = output
        self._pending, self._wake, self._running = {}, threading.Condition(), True

    def request(self, client) -> None:
        with self._wake:
            self._pending[client.client_id] = client
            self._wake.notify()

    def forget(self, client) -> None:
        with self._wake:
            self._pending.pop(client.client_id, None)

    def stop(self) -> None:
        with self._wake:
            self._running = False
            self._wake.notify()

    def next_client(self):
        """The next marked client (waiting for one), or None once stopped."""
        with self._wake:
            while self._running and not self._pending:
                self._wake.wait()
            return self._pending.pop(next(iter(self._pending))) if self._running else None

    def render(self, client) -> None:
        """Render one client's current camera state and send it."""
        camera = client.camera
        if camera.update_timestamp == 0.0 or self.renderer.scene is None:
            return  # no state from the browser yet, or no scene (`Served.show` brings one)
        try:
            image, seconds = self.renderer.frame(camera.position, camera.wxyz, camera.fov,
                                                 camera.aspect, int(self.max_size()),
                                                 self.output())
            client.scene.set_background_image(image, format="jpeg", jpeg_quality=90)
            self.report(f"{image.shape[1]}x{image.shape[0]}, {1000 * seconds:.0f} ms "
                        f"(a new size compiles)")
        except Exception as e:  # shown in the page; the next camera change tries again
            self.report(f"render failed: {type(e).__name__}: {e}")

    def run(self) -> None:
        while (client := self.next_client()) is not None:
            self.render(client)


class Served:
    """A viewer serving in threads (`serve(..., block=False)`): `port`, `show(scene, status)`
    to replace the scene (every browser's view is rendered again; the caller's thread only
    swaps a reference, so a training loop can call it often), `scene` and `status` (what it
    shows), `server` (viser's) and `stop()`."""

    def __init__(self, port: int, loop: FrameLoop, server, info, stop):
        self.port, self._loop, self.server, self._info, self.stop = port, loop, server, info, stop

    @property
    def scene(self):
        """The scene shown (None before the first)."""
        return self._loop.renderer.scene

    @property
    def status(self) -> str:
        """The status text above the frame reports."""
        return self._info.content

    def show(self, scene, status: str | None = None) -> None:
        """Render `scene` from now on (Gaussians of any size: a new size compiles once);
        `status`, when given, is shown in the page above the frame reports."""
        self._loop.renderer.scene = scene
        if status is not None:
            self._info.content = status
        for client in self.server.get_clients().values():
            self._loop.request(client)


def serve(scene, cameras, *, start: int = 0, host: str = "0.0.0.0", port: int = 8080,
          max_size: int = 1024, output: str = "image", block: bool = True,
          headroom: float = 1.0, **render_kwargs):
    """Serve `scene` to browsers at http://HOST:PORT (the next free port if PORT is taken),
    new clients starting at `cameras[start]` looking at the scene's centre (module docstring),
    the cameras drawn as frusta (a click on one moves the view there; a checkbox hides them),
    showing `output` at first (one of `OUTPUTS`; a dropdown changes it);
    `render_kwargs` go to `lgs_jax.render`, `headroom` sizes the pair buffer when a view
    outgrows it (`video.render_output`). `scene` None shows nothing until `Served.show` brings
    one (a scene in training; new clients look at the point nearest the cameras' axes). Prints
    the address. With `block`, serve until Ctrl-C and return None; else return a `Served`:
    the server runs in threads until its `stop()`."""
    if output not in OUTPUTS:
        raise ValueError(f"output: expected one of {OUTPUTS}, got {output!r}")
    if not (isinstance(port, int) and not isinstance(port, bool) and 1 <= port <= 65535):
        raise ValueError(f"port: expected a TCP port from 1 to 65535, got {port!r}")
    try:
        import viser
    except ImportError:
        raise RuntimeError('the viewer needs viser: pip install "lgs_jax[viewer]"') from None
    server = viser.ViserServer(host=host, port=port, verbose=False)
    first = [cameras[start]] + [c for i, c in enumerate(cameras) if i != start]
    _initial_view(server, first[0], look_target(first, scene))
    size = server.gui.add_slider("max size", min=64, max=4096, step=16,
                                 initial_value=int(max_size))
    output = server.gui.add_dropdown("output", OUTPUTS, initial_value=output)
    frusta = add_cameras(server.scene, cameras, frustum_scale(cameras))
    shown = server.gui.add_checkbox("show cameras", initial_value=True)
    shown.on_update(lambda _: [setattr(f, "visible", shown.value) for f in frusta])
    status = server.gui.add_markdown("")
    info = server.gui.add_markdown("waiting for a camera")
    loop = FrameLoop(FrameRenderer(scene, headroom, **render_kwargs), lambda: size.value,
                     lambda text: setattr(info, "content", text), lambda: output.value)

    def connect(client) -> None:
        client.camera.on_update(lambda _: loop.request(client))
        loop.request(client)

    server.on_client_connect(connect)
    server.on_client_disconnect(loop.forget)
    again = lambda _: [loop.request(c) for c in server.get_clients().values()]
    size.on_update(again)
    output.on_update(again)
    worker = threading.Thread(target=loop.run, name="lgs_jax-viewer", daemon=True)
    worker.start()

    def stop() -> None:
        loop.stop()
        worker.join()
        server.stop()

    print(f"viewer: http://localhost:{server.get_port()} (Ctrl-C stops)", flush=True)
    served = Served(server.get_port(), loop, server, status, stop)
    if not block:
        return served
    wait(served)
    return None


def wait(served: Served) -> None:
    """Keep serving until Ctrl-C, then stop."""
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        served.stop()
