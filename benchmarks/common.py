"""What every benchmark (and the timing in scripts/ and numerics/) shares: where the data is,
timing, PSNR, compiled memory, scene specs and the rows (backend, config) benchmarks compare.

Timing: `median_ms` calls every function once untimed (compilation, warm-up), then `repeat`
rounds in which every function runs once, in turn, so that drift in the machine's speed hits all
of them alike; each function must block until its work is done (`jax.block_until_ready`,
`torch.cuda.synchronize`). Compare rows of one run, not across runs.

Scene specs (`parse_scene`, `--scene` of the benchmarks):
  NAME@WxH[#VIEW]                a scene of `FILES` under the data folder (guitar, lego_sh3), view
                                 VIEW (default 0) of its cameras at WxH;
  NAME                           a named scene of `SCENES` (size, view and densification fixed);
  LABEL=PLY:CAMERAS@WxH[#VIEW]   any PLY and cameras file (paths as given);
  default@WxH[#VIEW]             the bundled scene (lgs_jax.default_scene) and camera;
  synthetic:N@WxH                N random Gaussians (lgs_jax.synthetic.random_scene).
Cameras are loaded at WxH with `lgs_jax.load_cameras(..., width=W, height=H)`.
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import time

import numpy as np

import lgs_jax
from lgs_jax.synthetic import densified, random_scene, synthetic_camera

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
"""The repository root."""
DATA = os.path.normpath(os.path.join(ROOT, "..", "shared", "data"))
"""Default folder of the real scenes: `shared/data` beside the repository (`--data` to change)."""

C = lgs_jax.RasterConfig


# ------------------------------------------------------------------------------------ timing

def median_ms(fns: dict, repeat: int, warmup: bool = True) -> dict:
    """{name: median ms} of each blocking callable over `repeat` rounds, all callables in turn
    within each round, after one untimed call each (unless `warmup` is False)."""
    if warmup:
        for f in fns.values():
            f()
    times = {name: [] for name in fns}
    for _ in range(repeat):
        for name, f in fns.items():
            t0 = time.perf_counter()
            f()
            times[name].append(time.perf_counter() - t0)
    return {name: 1e3 * statistics.median(t) for name, t in times.items()}


def timed(f, *args):
    """(f(*args) blocked until ready, seconds it took): the first call of a jitted function is
    its compile time."""
    import jax

    t0 = time.perf_counter()
    out = jax.block_until_ready(f(*args))
    return out, time.perf_counter() - t0


def psnr(a, b, peak: float = 1.0) -> float:
    """PSNR of a against b in dB (float64; inf where they are equal)."""
    mse = float(np.mean(np.square(np.asarray(a, np.float64) - np.asarray(b, np.float64))))
    return float("inf") if mse == 0 else float(10 * np.log10(peak**2 / mse))


def compiled_mib(f, *args, arguments: bool = False) -> float | None:
    """XLA's buffers for jitted f on args, MiB: temporaries + outputs (+ arguments)."""
    mem = f.lower(*args).compile().memory_analysis()
    if mem is None:
        return None
    total = mem.temp_size_in_bytes + mem.output_size_in_bytes
    return (total + (mem.argument_size_in_bytes if arguments else 0)) / 2**20


def device_line() -> str:
    """One line naming the device, CPU count and versions, for the head of a benchmark log."""
    import platform

    import jax

    dev = jax.devices()[0]
    return (f"device {dev.platform} ({dev.device_kind}); {os.cpu_count()} CPUs; JAX "
            f"{jax.__version__}; Python {platform.python_version()}")


def add_data_argument(parser):
    parser.add_argument("--data", default=DATA,
                        help=f"folder of the real scenes (default: {DATA})")


# ------------------------------------------------------------------------------------ scenes

FILES = {"guitar": ("guitar/guitar.ply", "guitar/orbit_cameras.json"),
         "lego_sh3": ("lego_sh3/lego_sh3.ply", "lego_sh3/lego_cameras.json")}
"""Real scenes under the data folder: PLY and cameras file."""

SCENES = {
    "guitar_720p": ("guitar", 1, 1280, 720),
    "guitar_4k": ("guitar", 1, 3840, 2160),
    "lego_800": ("lego_sh3", 1, 800, 800),
    "guitar_x16_1080p": ("guitar", 16, 1920, 1080),
    "lego_x16_1080p": ("lego_sh3", 16, 1920, 1080),
    "guitar_x64_1080p": ("guitar", 64, 1920, 1080),
    "guitar_x110_4k": ("guitar", 110, 3840, 2160),
    "synthetic4M_1080p": ("synthetic:4000000", 1, 1920, 1080),
    "synthetic10M_4k": ("synthetic:10000000", 1, 3840, 2160),
}
"""Named scenes: name -> (base scene, densify factor, width, height); the base is a `FILES` key
(view 0 of its cameras, densified by lgs_jax.synthetic.densified when the factor is > 1) or
"synthetic:N"."""


def load_scene(name: str, data: str = DATA):
    """(Gaussians, Camera) of a `SCENES` entry."""
    base, k, w, h = SCENES[name]
    if base.startswith("synthetic:"):
        return random_scene(int(base.split(":")[1])), synthetic_camera(w, h)
    ply, cams = FILES[base]
    g = lgs_jax.load_ply(os.path.join(data, ply))
    cam = lgs_jax.load_cameras(os.path.join(data, cams), width=w, height=h)[0]
    return (densified(g, k, seed=0) if k > 1 else g), cam


@dataclasses.dataclass
class Case:
    name: str
    scene: object
    camera: object


def parse_scene(spec: str, data: str = DATA) -> Case:
    """A scene spec (module docstring) as a `Case` (name, Gaussians, Camera)."""
    if spec in SCENES:
        return Case(spec, *load_scene(spec, data))
    spec, _, size = spec.partition("@")
    view = 0
    if "#" in size:
        size, view = size.split("#")
        view = int(view)
    width, height = (int(v) for v in size.split("x")) if size else (None, None)
    if spec == "default":
        return Case("default", lgs_jax.default_scene(),
                    lgs_jax.default_camera(view, width, height))
    if spec.startswith("synthetic:"):
        n = int(spec.split(":")[1])
        return Case(f"synthetic{n}", random_scene(n), synthetic_camera(width or 1280,
                                                                        height or 720))
    if spec in FILES:
        name, (ply, cams) = spec, (os.path.join(data, f) for f in FILES[spec])
    elif "=" in spec:
        name, _, paths = spec.partition("=")
        ply, _, cams = paths.partition(":")
    else:
        raise ValueError(f"scene spec {spec!r}: expected one of {sorted(SCENES)}, "
                         f"NAME@WxH with NAME in {sorted(FILES)}, LABEL=PLY:CAMERAS@WxH, "
                         "default@WxH or synthetic:N@WxH")
    return Case(name, lgs_jax.load_ply(ply),
                lgs_jax.load_cameras(cams, width=width, height=height)[view])


# -------------------------------------------------------------------------------------- rows

TILES_ROWS = {  # the paper's Table IV (ablation) and Table V (precision) rows, on `tiles`
    "reference": ("reference", C()),
    "tiles:baseline": ("tiles", C(hoist=False, warp_cull=False)),
    "tiles:+hoisting": ("tiles", C(warp_cull=False)),
    "tiles:+warp_culling": ("tiles", C()),
    "tiles:+coherent_blending": ("tiles", C(blend="fast")),
    "tiles:difference+culling": ("tiles", C(hoist=False)),
    "tiles:local_center": ("tiles", C(origin="center")),
    "tiles:global_coords": ("tiles", C(local_coords=False)),
}
"""name -> (backend, config): every backend and Local-GS switch the CPU benchmark compares."""

ABLATION_ROWS = {  # the paper's Table IV for the Pallas kernels (Mosaic GPU on a GPU)
    "brute": ("brute", C()),
    "pallas_vanilla": ("pallas_vanilla", C()),
    "pallas:baseline": ("pallas", C(hoist=False, warp_cull=False)),
    "pallas:+hoisting": ("pallas", C(warp_cull=False)),
    "pallas:+warp_culling": ("pallas", C()),
    "pallas:+coherent_blending": ("pallas", C(blend="fast")),
    "pallas:difference+culling": ("pallas", C(hoist=False)),
    "pallas:global_coords": ("pallas", C(local_coords=False)),
}
"""name -> (backend, config): the cumulative ablation on the Pallas kernels (baseline: the
Local-GS kernel's structure with the difference form and no strip masks; `pallas_vanilla`: the
original rasterizer's structure) and `brute` (every Gaussian at every pixel: small scenes)."""

PALLAS_ROWS = {  # "auto" rows run what KernelConfig's auto_* picks on this device
    "pallas": ("pallas", C()),
    "pallas:fast": ("pallas", C(blend="fast")),
    "pallas:no_cull": ("pallas", C(warp_cull=False)),
    "pallas:triton": ("pallas", C(kernel="triton")),
    "pallas:mosaic": ("pallas", C(kernel="mosaic")),
    "pallas:mosaic:fast": ("pallas", C(kernel="mosaic", blend="fast")),
    "pallas_vanilla": ("pallas_vanilla", C()),
    "pallas_vanilla:triton": ("pallas_vanilla", C(kernel="triton")),
    "pallas_vanilla:mosaic": ("pallas_vanilla", C(kernel="mosaic")),
    "tiles": ("tiles", C()),
}
"""name -> (backend, config): the forward rows of the GPU benchmark against gsplat."""

GRAD_ROWS = {name: PALLAS_ROWS[name] for name in (
    "pallas", "pallas:fast", "pallas:triton", "pallas:mosaic", "pallas:mosaic:fast",
    "pallas_vanilla", "pallas_vanilla:triton", "pallas_vanilla:mosaic", "tiles")}
GRAD_ROWS["reference"] = ("reference", C())
"""name -> (backend, config): the forward + backward rows of the GPU benchmark."""


def pipeline_stages(g, cam, capacity: int):
    """The XLA stages shared by every tiled backend, as jitted callables for timing: (projected
    Gaussians, sorted bins, {"project", "emit", "sort": zero-argument callables returning the
    stage's arrays}) for scene `g` through `cam` with a pair buffer of `capacity`."""
    import jax

    from lgs_jax import binning
    from lgs_jax.layout import tile_grid
    from lgs_jax.projection import project

    w, h = cam.width, cam.height
    n_tiles = int(np.prod(tile_grid(w, h)))
    proj = jax.jit(project)
    emit = jax.jit(lambda p: binning.emit_pairs(p, w, h, capacity))
    sort = jax.jit(lambda t, i: binning.sort_pairs(t, i, n_tiles))
    p = proj(g, cam)
    bins = jax.jit(lambda p: binning.bin_gaussians(p, w, h, capacity))(p)
    e = emit(p)
    return p, bins, {"project": lambda: proj(g, cam), "emit": lambda: emit(p),
                     "sort": lambda: sort(e.tile, e.gauss)}


def torch_peak_mib(f) -> float:
    """Peak CUDA memory (MiB) torch allocates during one call of f, above what it held before."""
    import torch

    torch.cuda.synchronize()
    torch.cuda.reset_peak_memory_stats()
    base = torch.cuda.memory_allocated()
    f()
    torch.cuda.synchronize()
    return (torch.cuda.max_memory_allocated() - base) / 2**20
