"""Training: Gaussians fitted to a capture with a densification strategy, in static shapes.

    python -m lgs_jax fit --data DIR --out RUN [--recipe default|fast]
        [--strategy default|mcmc|budget] ...
    lgs_jax.train.fit(FitConfig(data=DIR, out=RUN, steps=N, ...))

Modules (each usable alone):
  `config`     `FitConfig` (a run's whole configuration, from which the command line is
               generated), `Recipe` (what a step computes), `Setup` (the jitted functions' key).
  `options`    configuration fields that document and check themselves.
  `losses`     SSIM (3DGS's zero-padded one for the loss, scikit-image's for checks), the loss.
  `pool`       the fixed-size pool of Gaussians with an active mask; growth by doubling.
  `optim`      Adam per group with gsplat simple_trainer's rates; moments that follow Gaussians.
  `ops`        clone, split, prune, opacity reset, relocation, sampling, noise (gsplat's ops).
  `strategy`   the `Strategy` interface, `DefaultStrategy` and `MCMCStrategy` (gsplat 1.5.3).
  `budget`     `BudgetStrategy`: MCMC on Taming 3DGS's budget curve, unseen Gaussians relocated.
  `recipes`    the recipes by name (default: gsplat's; fast) and the strategies by name.
  `levels`     coarse to fine: the training images at a few fixed sizes, each from a fixed step.
  `early_stop` the end of a run when its training loss stops falling.
  `init`       initial Gaussians from SfM points or random ones (gsplat's simple_trainer).
  `step`       `train_step` (the jitted training step) and refinement; renders of the pool.
  `ahead`      `Stepper`: a jitted step compiled ahead for its next buffer size.
  `loop`       `fit`: the loop; `state` its state (fresh, resumed, saved), `checkpoint` the
               checkpoint files, `rundir` the run folder (checks, lock), `outputs` what a run
               leaves, `report` the progress bar and metrics, `interrupt` Ctrl-C.
  `evaluate`   a scene's PSNR and SSIM on a capture's views (`python -m lgs_jax eval`).
  `camera_opt` the training views' pose deltas (`Recipe.pose_opt`, gsplat's --pose_opt).
  `color_opt`  an affine colour correction per training view (`Recipe.color_opt`).
  `bilateral_grid` a bilateral grid of colour maps per training view (`Recipe.bilateral_grid`,
               gsplat's --use_bilateral_grid).
  `appearance` appearance embeddings: per-Gaussian features, per-view embeddings and the
               head they share (`Recipe.app_opt`, gsplat's --app_opt).
  `view_params` the views' own parameters above as one state, their rows and updates.
  `feed`       a capture made ready for `fit` (one or several image sizes), the view order.
"""

from .checkpoint import CheckpointError
from .config import FitConfig, Recipe, Setup
from .evaluate import evaluate
from .interrupt import Interrupted
from .loop import fit
from .losses import loss_fn, psnr, ssim
from .optim import optimizer
from .pool import Pool, active_gaussians, from_gaussians, render_gaussians, sh_mask
from .rundir import RunDirError, check_out, run_dir_problem
from .step import train_step
from .budget import BudgetStrategy
from .recipes import STRATEGIES
from .strategy import DefaultStrategy, MCMCStrategy, StepInfo, Strategy

__all__ = ["STRATEGIES", "BudgetStrategy", "CheckpointError", "DefaultStrategy", "FitConfig",
           "Interrupted", "MCMCStrategy", "Pool", "Recipe", "RunDirError", "Setup", "StepInfo",
           "Strategy",
           "active_gaussians", "check_out", "evaluate", "fit", "from_gaussians", "loss_fn",
           "optimizer", "psnr", "render_gaussians", "run_dir_problem", "sh_mask", "ssim",
           "train_step"]
