"""The training recipe (`Settings`) and the static description of one run (`Setup`)."""

from __future__ import annotations

import dataclasses

from ..config import RasterConfig
from .strategy import DefaultStrategy, Strategy


@dataclasses.dataclass(frozen=True)
class Settings:
    """gsplat simple_trainer's recipe (3DGS's rates), and how `fit` runs.

    Learning rates per group (Adam, `optim.optimizer`): means lr_means · scene_scale decaying to
    lr_means_decay of that over the run; the others constant. ssim_lambda: weight of 1 − SSIM in
    the loss; ssim_padding: "same" (3DGS, the default) or "valid" (gsplat's simple_trainer),
    `losses.ssim`. convention: the compositing rule of training and evaluation renders
    (`RasterConfig.convention`: "3dgs", alpha cap 0.99, or "gsplat", 0.999 as gsplat's trainer
    renders). antialiased: train and evaluate with `RasterConfig.antialiased` (gsplat's
    rasterize_mode="antialiased"; a scene trained so should be rendered so). sh_every: one more
    SH band every sh_every steps up to sh_degree. batch: views per step. eval_every /
    checkpoint_every: steps between held-out evaluations / checkpoints.
    init_points, init_extent: the random start of datasets without SfM points (`init.py`):
    that many points in a cube of half-width init_extent · scene_scale; None: 3.0 (gsplat) for
    captures, 0.25 for NeRF-synthetic scenes (white background; 3DGS's ±1.3 cube on Lego).
    pair_headroom (>= 1): the pair capacity of a training view is
    `pair_capacity(pairs, pair_headroom)` of the pairs it needs, at the start (first training
    view) and whenever a step overflows (that step's largest view; the step is redone, nothing
    is dropped). Every growth is a recompile of the step (about 20 s on an H200) and every
    per-pair pass costs in proportion to the capacity. 3 (the default) grows about once per 3x
    growth of the pairs: on the skull capture (7k steps, pairs grow 27x) 3 growths and 157 s
    against 8 and 244 s at 1.5, the steps themselves within 2% (9.70 against 9.54 ms;
    BENCHMARKS.md §7, "Dec 2, midday"). Smaller values mean fewer pair slots and more
    recompiles. Not part of the checkpointed recipe (it changes no result).
    row_headroom (None or >= 1): the Pallas backward's buffer of per-pair gradient rows (48
    bytes per row and block of a tile, the largest buffer of a step at scale). None (the
    default): a row per pair slot, which nothing can overflow. A number h: only the pairs some
    pixel reached take a row (`render`'s `stats.pairs_walked`: 15–30% of the pairs at 1M–10M
    Gaussians, BENCHMARKS.md §7), so the buffer starts at `pair_capacity(walked, h)` of the
    first training view's walked pairs (one forward render before the first step) and grows the
    same way whenever a view walks more (the step is redone, a recompile, logged, as for the
    pairs; `ahead.Sizes`): less memory, the same bits, a compile per growth. Not part of the
    checkpointed recipe.
    stream_images (None or a bool): keep only each step's training views on the device,
    copying the next step's while a step runs (`data.TrainViews`), instead of the whole
    capture (float32: 12 bytes a pixel, 7.5 GB for 300 views at 1920x1080). None (the
    default): stream when the images would take more than an eighth of the device's memory
    (`data.streams`). The same bits either way; not part of the checkpointed recipe.
    pose_opt: also optimize each training view's pose (`camera_opt`: gsplat's --pose_opt),
    at rate lr_pose · sqrt(batch) with L2 weight decay pose_reg (gsplat's defaults).
    color_opt: also optimize an affine colour correction of each training view's render
    (`color_opt`: exposure and white balance that change between photos), centred over the
    views, at rate lr_color · sqrt(batch) with L2 weight decay color_reg (gsplat's app_opt
    rates); held-out views are evaluated at the views' average appearance.
    bilateral_grid: also optimize a bilateral grid of affine colour maps per training view
    (`bilateral_grid`: gsplat's --use_bilateral_grid, for camera processing that varies over
    the image), centred over the views, at rate lr_grid · sqrt(batch) (warmed up over 1000
    steps, decaying to 1%) with the grids' total variation weighted by grid_tv in the loss;
    held-out views are evaluated without a grid.
    app_opt: also optimize appearance embeddings (`appearance`: gsplat's --app_opt, for photos
    whose lighting changes in ways that differ over the scene): a feature per Gaussian (rate
    lr_features), an embedding per training view (rate lr_app · 10 · sqrt(batch)) and a head
    the views share (lr_app · sqrt(batch)), L2 weight decay app_reg on both; held-out views
    and scene.ply are the scene at the training views' average appearance.
    train_on_all: train on every view of the dataset, its held-out ones included (for a final
    scene); nothing is evaluated (held-out PSNR and SSIM are None).
    """

    lr_means: float = 1.6e-4
    lr_means_decay: float = 0.01
    lr_quats: float = 1e-3
    lr_log_scales: float = 5e-3
    lr_logit_opacities: float = 5e-2
    lr_sh_dc: float = 2.5e-3
    lr_sh_rest: float = 2.5e-3 / 20
    ssim_lambda: float = 0.2
    ssim_padding: str = "same"
    convention: str = "3dgs"
    antialiased: bool = False
    sh_every: int = 1000
    sh_degree: int = 3
    batch: int = 1
    eval_every: int = 500
    checkpoint_every: int = 1000
    init_points: int = 100_000
    init_extent: float | None = None
    pair_headroom: float = 3.0
    row_headroom: float | None = None
    stream_images: bool | None = None
    pose_opt: bool = False
    train_on_all: bool = False
    lr_pose: float = 1e-5
    pose_reg: float = 1e-6
    color_opt: bool = False
    lr_color: float = 1e-3
    color_reg: float = 1e-6
    bilateral_grid: bool = False
    lr_grid: float = 2e-3
    grid_tv: float = 10.0
    app_opt: bool = False
    lr_app: float = 1e-3
    app_reg: float = 1e-6
    lr_features: float = 2.5e-3

    @property
    def raster(self) -> RasterConfig:
        """The `RasterConfig` of training and evaluation renders."""
        return RasterConfig(self.convention, antialiased=self.antialiased)


@dataclasses.dataclass(frozen=True)
class Setup:
    """What the jitted functions of one run depend on statically (hashable): the recipe, the
    strategy, the run length (the means' schedule), the scene scale, the backend, and the
    devices a step's views are split across (data parallel: `step.over_views`)."""

    settings: Settings = Settings()
    strategy: Strategy = DefaultStrategy()
    steps: int = 30_000
    scene_scale: float = 1.0
    backend: str = "tiles"
    devices: int = 1
