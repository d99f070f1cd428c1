"""A training run's whole configuration: `FitConfig` (what `fit` takes and the `fit` command line
is generated from, `lgs_jax.cli.options`), with `Recipe` (what each training step computes) and
the densification strategy (`strategy.Strategy`, a frozen dataclass of its own) nested in it;
`Setup`, the part the jitted functions depend on statically. Every field documents itself
(`options.option`: help, bounds) and is checked when the configuration is made.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import jax
import numpy as np

from ..config import CONVENTIONS, RasterConfig
from .losses import PADDINGS
from . import recipes
from .options import check, option
from .strategy import DefaultStrategy, Strategy

TRAIN_BACKENDS = ("reference", "tiles", "pallas", "pallas_vanilla")  # differentiable ones
FORM_BACKENDS = ("tiles", "pallas")  # those that honour Recipe.alpha_form; the others compute
# the difference form
ALPHA_FORMS = {  # Recipe.alpha_form -> the RasterConfig switches it sets
    "local": dict(hoist=True, local_coords=True),
    "global": dict(hoist=True, local_coords=False),
    "difference": dict(hoist=False),
}
PIXELS_PER_POINT = 4  # random start: a point per this many pixels of a training image ...
MAX_INIT_POINTS = 100_000  # ... at most this many (gsplat's count for NeRF-synthetic scenes)


@dataclasses.dataclass(frozen=True)
class Recipe:
    """What each training step computes: gsplat simple_trainer's recipe (3DGS's rates), or the
    fast recipe (`recipes`: images coarse to fine, several views per step, an early stop).

    Adam per parameter group (`optim.optimizer`); the views' own parameters (poses, colour
    corrections, bilateral grids, appearance embeddings: `view_params`) at their rates times
    sqrt(batch). Fields left None take recipe `name`'s value when the recipe is made
    (`recipes.fill`). A checkpoint records the recipe: a resumed run must share it.
    """

    name: Literal["default", "fast"] = option(
        "default", "the recipe whose values the options below change: default (gsplat "
                   "simple_trainer's) or fast (fewer steps, images coarse to fine, a Gaussian "
                   "budget, an early stop; see docs/training.md)", flag="--recipe")
    lr_means: float = option(1.6e-4, "means' learning rate, times the scene scale", low=0)
    lr_means_decay: float = option(
        0.01, "the means' rate decays exponentially to this fraction over the run", low=0)
    lr_quats: float = option(1e-3, "rotations' learning rate", low=0)
    lr_log_scales: float = option(5e-3, "log-scales' learning rate", low=0)
    lr_logit_opacities: float = option(5e-2, "opacity logits' learning rate", low=0)
    lr_sh_dc: float = option(2.5e-3, "SH band 0's learning rate", low=0)
    lr_sh_rest: float = option(2.5e-3 / 20, "higher SH bands' learning rate", low=0)
    ssim_lambda: float = option(0.2, "weight of 1 − SSIM in the loss, (1 − λ)·L1 + λ·(1 − SSIM)",
                                low=0, high=1)
    ssim_padding: str = option(
        "same", "SSIM of the loss: same (3DGS: zero-padded, every pixel) or valid (gsplat's "
                "simple_trainer)", choices=PADDINGS)
    convention: str = option(
        "3dgs", "compositing rule of training and evaluation renders (alpha cap 0.99, or "
                "gsplat's 0.999)", choices=CONVENTIONS)
    antialiased: bool = option(
        False, "train and evaluate with antialiased renders (gsplat's --antialiased: "
               "opacities scaled so that the 0.3-pixel dilation keeps each Gaussian's "
               "integral); render the result with --antialiased too")
    alpha_form: Literal["local", "global", "difference"] = option(
        "local", "how training and evaluation renders evaluate each pair's exponent ln α "
                 "(the tiles and pallas backends; reference and pallas_vanilla always use the "
                 "difference form): local (the paper's hoisted quadratic, Eq. 8-10, in "
                 "tile-local coordinates, Eq. 1-3), global (the same quadratic in global "
                 "screen coordinates: the paper's \"w/o Local Coord\", Table V) or difference "
                 "(the original 3DGS form, -½ dᵀ Σ⁻¹ d of the pixel's offset d from the "
                 "centre: no hoisting)")
    sh_every: int | None = option(None, f"steps between SH degrees (one band more each time) "
                                        f"(default: the recipe's: {recipes.said('sh_every')})",
                                  low=1)
    sh_degree: int = option(3, "highest SH degree of the colours (0: view-independent)",
                            low=0, high=3)
    batch: int | None = option(None, f"views per step (default: the recipe's: "
                                     f"{recipes.said('batch')})", low=1)
    levels: int | None = option(
        None, f"coarse to fine (DashGaussian): train on the images downscaled by 2^(L-1), ..., "
              f"2, then at full resolution, each level from a fixed step (each image size "
              f"compiles its own step); 1: full resolution throughout (default: "
              f"the recipe's: {recipes.said('levels')})", low=1, high=4)
    full_resolution_at: float = option(
        0.5, "with levels > 1: the fraction of the steps after which training runs at full "
             "resolution; the coarser levels share the steps before it equally", low=0, high=1)
    early_stop: bool | None = option(
        None, f"stop when the training loss stops falling: its mean over the last stop_window "
              f"steps less than stop_gain below the window's before (training views only; "
              f"checked every stop_window steps at full resolution) (default: the recipe's: "
              f"{recipes.said('early_stop')})")
    stop_window: int = option(400, "the early stop's window, in steps", low=1)
    stop_gain: float = option(
        0.002, "the early stop's least relative fall of the mean training loss per window",
        low=0)
    pose_opt: bool = option(
        False, "also optimize each training view's camera pose (gsplat's --pose_opt: a 9-D "
               "delta per view); held-out views keep their poses")
    lr_pose: float = option(1e-5, "pose deltas' learning rate", low=0)
    pose_reg: float = option(1e-6, "pose deltas' L2 weight decay", low=0)
    color_opt: bool = option(
        False, "also optimize an affine colour correction of each training view (exposure "
               "and white balance that change between photos); held-out views render at the "
               "views' average appearance; colors.json holds the corrections")
    lr_color: float = option(1e-3, "colour corrections' learning rate", low=0)
    color_reg: float = option(1e-6, "colour corrections' L2 weight decay", low=0)
    bilateral_grid: bool = option(
        False, "also optimize a bilateral grid of affine colour maps per training view "
               "(gsplat's --use_bilateral_grid: 16x16 cells by 8 brightness levels, for camera "
               "processing that varies over the image); held-out views render without one; "
               "bilateral_grids.npz holds the grids")
    lr_grid: float = option(2e-3, "bilateral grids' learning rate (warmed up over 1000 steps, "
                                  "decaying to 1%)", low=0)
    grid_tv: float = option(10.0, "weight of the grids' total variation in the loss", low=0)
    app_opt: bool = option(
        False, "also optimize appearance embeddings (gsplat's --app_opt: a feature per "
               "Gaussian, an embedding per training view and a small MLP giving each "
               "Gaussian's colour change in each view, for lighting that changes over the "
               "scene between photos); held-out views and scene.ply are the scene at the "
               "views' average appearance; appearance.npz holds the rest")
    lr_app: float = option(1e-3, "appearance head's learning rate (the embeddings' 10x)", low=0)
    app_reg: float = option(1e-6, "appearance embeddings' and head's L2 weight decay", low=0)
    lr_features: float = option(2.5e-3, "appearance features' learning rate", low=0)

    def __post_init__(self):
        check(self)
        recipes.fill(self, self.name)

    @property
    def raster(self) -> RasterConfig:
        """The `RasterConfig` of training and evaluation renders (`alpha_form`'s switches:
        `ALPHA_FORMS`)."""
        return RasterConfig(self.convention, antialiased=self.antialiased,
                            **ALPHA_FORMS[self.alpha_form])


@dataclasses.dataclass(frozen=True)
class FitConfig:
    """Everything a `fit` run is: the data and the run folder, the run length, the recipe, the
    strategy, the start, the sizes of the step's buffers, the devices, and when to evaluate
    and checkpoint. Frozen and hashable; each field's help is its documentation (`python -m
    lgs_jax fit --help` shows them); bad values raise `ValueError` naming the field. steps and
    strategy left None take the recipe's (`recipes.fill`) when the configuration is made."""

    data: str = option(help="dataset folder (or transforms json)")
    out: str = option(help="run directory (new or empty, unless --resume or --overwrite)")
    steps: int | None = option(
        None, f"training steps (default: the recipe's: {recipes.said('steps')}; fast on a real "
              f"capture without SfM points: {recipes.WIDE_START_VALUES['fast']['steps']})", low=0)
    recipe: Recipe = Recipe()
    strategy: Strategy | None = option(
        None, "densification: default (3DGS clone/split/prune, gsplat's DefaultStrategy), "
              "mcmc (3DGS as MCMC, gsplat's MCMCStrategy, with its recipe: init opacity 0.5, "
              "scale 0.1, regularisers 0.01) or budget (MCMC with Taming 3DGS's budget "
              "schedule and unseen Gaussians relocated, `budget.BudgetStrategy`) (default: the "
              f"recipe's: {recipes.said('strategy')}; fast on a real capture without SfM "
              "points: default, `recipes.WIDE_START_VALUES`)")
    max_gaussians: int = option(1_000_000, "cap on the number of Gaussians (the pool's; the "
                                           "command line's mcmc takes it as cap_max)", low=1)
    pool_size: int | None = option(
        None, "initial pool slots (default: the most Gaussians the strategy can reach in the "
              "run, e.g. MCMC's, so that the pool never grows; the next power of two above the "
              "initial count where it cannot say; the pool doubles when it must, recompiling "
              "once each time)", low=1)
    init_points: int | None = option(
        None, f"random initial points for datasets without SfM points (default: one per "
              f"{PIXELS_PER_POINT} pixels of the largest training image, at most "
              f"{MAX_INIT_POINTS})", low=1)
    init_extent: float | None = option(
        None, "the random points fill a cube of this half-width times the scene scale "
              "(default: 0.25 for NeRF-synthetic scenes, 3DGS's cube on Lego; 3 otherwise, "
              "gsplat's)", low=0)
    downscale: int = option(1, "integer image downscale at load", low=1)
    crop: tuple[int, int, int, int] | None = option(
        None, "train and evaluate on this window of every image (quick checks)", low=0,
        metavar=("X0", "Y0", "W", "H"))
    uint8_images: bool | None = option(
        None, "hold the images as 8-bit values (a quarter of the memory, host and device), "
              "rounded after compositing, undistortion and --downscale (as an 8-bit image "
              "file of that size would be); without those, the same results (default: 8-bit "
              "where every image file is 8-bit, float32 where one has 16 bits)")
    train_on_all: bool = option(
        False, "train on every view, the held-out ones too (a final scene; nothing is "
               "evaluated)")
    seed: int = option(0, "seed of the start, the view order and the strategies' draws", low=0)
    backend: str | None = option(None, "differentiable backend (default: pallas on GPUs, tiles "
                                       "elsewhere)", choices=TRAIN_BACKENDS)
    precision: Literal["float32", "float64"] = option(
        "float32", "the arithmetic of training: the Gaussians, their optimizer state, the "
                   "images, the renders and their gradients, the loss (float64 needs "
                   "jax_enable_x64, which the command line turns on; every backend "
                   "computes in it)")
    devices: int = option(1, "split each step's views across this many devices (data "
                             "parallel; --batch a multiple of it); with --gaussian-devices D, "
                             "across this many rows of D devices each", low=1)
    gaussian_devices: int = option(
        1, "split the Gaussians and their optimizer state across this many devices (Gaussian "
           "parallel, for scenes larger than one device: one model, one checkpoint; "
           "docs/multi-gpu.md); the same results as one device up to the rounding of the "
           "gradients' sums; with --devices V, a mesh of V x D devices", low=1)
    pair_headroom: float = option(
        3.0, "pair buffer size as a multiple of a view's pairs, at the start and at each "
             "growth (a recompile); larger: fewer recompiles, larger buffers", low=1)
    row_headroom: float | None = option(
        None, "the Pallas backward's gradient rows: this multiple of the pairs a pair "
              "buffer is sized for (and of the walked pairs, growing them where a view walks "
              "more: a recompile); the same results; larger: fewer recompiles, more memory "
              "(default: 1.5 on one Gaussian device; with Gaussian parallel a row per pair "
              "slot)", low=1)
    stream_images: bool | None = option(
        None, "keep only each step's views on the device (copied while the step before runs) "
              "instead of the whole capture; the same results (default: on a GPU, and on "
              "a CPU for captures over 2 GiB)")
    compile_ahead: Literal["thread", "process", "off"] | None = option(
        None, "compile the step for a grown pair buffer ahead: in a background thread, in a "
              "child process through the persistent compilation cache (no contention for "
              "Python's lock), or off (compiled when a step needs it); the same results "
              "(default: thread on a GPU, off elsewhere)", exclusive="compile_ahead")
    eval_every: int = option(500, "steps between held-out evaluations", low=1)
    checkpoint_every: int = option(
        1000, "steps between checkpoints (also written at the end and on Ctrl-C)", low=1)
    resume: bool = option(False, "continue from OUT's checkpoint (with the options it was "
                                 "started with; --steps may grow)", exclusive="again")
    overwrite: bool = option(False, "delete OUT's previous run (its checkpoint, metrics and "
                                    "renders)", exclusive="again")

    def __post_init__(self):
        check(self)
        recipes.fill(self, self.recipe.name)
        if self.resume and self.overwrite:
            raise ValueError("resume, overwrite: they exclude each other")
        if self.recipe.batch % self.devices:
            raise ValueError(f"devices: {self.devices} devices split recipe.batch = "
                             f"{self.recipe.batch} views unevenly; make the batch a multiple "
                             f"of them")
        gaussian_parallel_problem(self)

    @property
    def image_dtype(self):
        """`load_dataset`'s dtype for `uint8_images`: np.uint8, np.float32 or "auto"."""
        return {None: "auto", True: np.uint8, False: np.float32}[self.uint8_images]

    def start_points(self, pixels: int) -> int:
        """The random start's point count for training images of at most `pixels` pixels
        (`init_points`, or its default)."""
        if self.init_points is not None:
            return self.init_points
        return max(1, min(MAX_INIT_POINTS, pixels // PIXELS_PER_POINT))


def gaussian_parallel_problem(config: FitConfig) -> None:
    """Raise `ValueError` naming the fields that Gaussian parallel training
    (`gaussian_devices` > 1, `lgs_jax.train.sharded`) does not combine with."""
    if config.gaussian_devices == 1:
        return
    refused = [("recipe.app_opt", config.recipe.app_opt, "each view's colours of every "
                                                         "Gaussian are not built sharded"),
               ("row_headroom", config.row_headroom is not None, "the sharded render keeps a "
                                                                 "backward row per pair slot"),
               ("compile_ahead", config.compile_ahead in ("thread", "process"),
                "a step is compiled when it needs a grown buffer"),
               ("precision", config.precision == "float64", "the sharded render computes in "
                                                            "float32")]
    for name, wrong, why in refused:
        if wrong:
            raise ValueError(f"{name}: not with gaussian_devices = {config.gaussian_devices} "
                             f"({why})")


def devices_problem(config: FitConfig) -> None:
    """Raise `ValueError` naming the field where the run's mesh, `devices` x
    `gaussian_devices`, needs more devices than `jax.devices()` has."""
    have, kind = len(jax.devices()), jax.default_backend()
    for name, count in (("devices", config.devices), ("gaussian_devices",
                                                      config.gaussian_devices)):
        if count > have:
            raise ValueError(f"{name}: expected an int from 1 to {have} (the {kind} devices "
                             f"here), got {count!r}")
    need = config.devices * config.gaussian_devices
    if need > have:
        raise ValueError(f"devices, gaussian_devices: a mesh of {config.devices} x "
                         f"{config.gaussian_devices} needs {need} devices; there are {have} "
                         f"{kind} devices here")


LOOP_ONLY = dict(name="default", levels=1, full_resolution_at=0.5, early_stop=False,
                 stop_window=400, stop_gain=0.002)
"""`Recipe` fields no training step reads (`Setup.for_step`), at the values a step is keyed by:
the recipe's name (its defaults are filled in by then), the image levels' schedule (a level's
image size is in the step's shapes) and the early stop."""


ROW_HEADROOM = 1.5
"""`FitConfig.row_headroom` where it is None, on one Gaussian device (`row_headroom`)."""


def row_headroom(config: FitConfig) -> float | None:
    """The headroom a run sizes the backward's rows with: `config.row_headroom`, or where that
    is None, `ROW_HEADROOM` on one Gaussian device and None (a row per pair slot, which the
    sharded render keeps) with Gaussian parallel."""
    if config.row_headroom is not None or config.gaussian_devices > 1:
        return config.row_headroom
    return ROW_HEADROOM


@dataclasses.dataclass(frozen=True)
class Setup:
    """What the jitted functions of one run depend on statically (hashable): the recipe, the
    strategy, the run length (the means' schedule), the scene scale, the backend, the
    devices a step's views are split across (data parallel: `step.over_views`) and those its
    Gaussians are split across (Gaussian parallel: `sharded`; both: the views split over the
    rows of a `devices` x `gaussian_devices` mesh, `sharded.mesh_of`). Raises `ValueError` for a
    `recipe.alpha_form` that `backend` does not compute."""

    recipe: Recipe = Recipe()
    strategy: Strategy = DefaultStrategy()
    steps: int = 30_000
    scene_scale: float = 1.0
    backend: str = "tiles"
    devices: int = 1
    gaussian_devices: int = 1
    precision: str = "float32"

    def __post_init__(self):
        if self.recipe.alpha_form == "global" and self.backend not in FORM_BACKENDS:
            raise ValueError(f"recipe.alpha_form: 'global' needs a backend of {FORM_BACKENDS}; "
                             f"{self.backend!r} computes the difference form")
        if self.precision == "float64" and not jax.config.jax_enable_x64:
            raise ValueError("precision: float64 needs jax_enable_x64 (jax.config.update("
                             "'jax_enable_x64', True) before any JAX work; `fit "
                             "--precision float64` does it); without it JAX computes in "
                             "float32")

    @property
    def for_step(self) -> "Setup":
        """This setup with the recipe's fields that only `fit`'s loop reads (`LOOP_ONLY`: the
        image levels' schedule and the early stop) at fixed values: the training step's
        static argument, so that runs differing only in them share the step's programs (one
        jit entry, one export entry) instead of compiling their own."""
        return dataclasses.replace(self, recipe=dataclasses.replace(self.recipe, **LOOP_ONLY))

    @property
    def dtype(self):
        """The training arithmetic's numpy dtype (`FitConfig.precision`)."""
        return np.dtype(self.precision)

    @classmethod
    def of(cls, config: FitConfig, scene_scale: float, default_backend: str) -> "Setup":
        """The setup of a run of `config` on data of `scene_scale`; its backend config.backend,
        or else `default_backend`."""
        backend = config.backend or default_backend
        return cls(config.recipe, config.strategy, config.steps, scene_scale, backend,
                   config.devices, config.gaussian_devices, config.precision)
