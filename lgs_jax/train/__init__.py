"""Training: Gaussians fitted to a capture with a densification strategy, in static shapes.

    python -m lgs_jax fit --data DIR --out RUN [--strategy default|mcmc] [--max-gaussians N]
        [--downscale K] [--steps N] [--resume | --overwrite]

Modules (each usable alone):
  `losses`     SSIM (3DGS's zero-padded one for the loss, scikit-image's for checks), the loss.
  `pool`       the fixed-size pool of Gaussians with an active mask; growth by doubling.
  `optim`      Adam per group with gsplat simple_trainer's rates; moments that follow Gaussians.
  `ops`        clone, split, prune, opacity reset, relocation, sampling, noise (gsplat's ops).
  `strategy`   the `Strategy` interface, `DefaultStrategy` and `MCMCStrategy` (gsplat 1.5.3).
  `init`       initial Gaussians from SfM points or random ones (gsplat's simple_trainer).
  `step`       the jitted training step and refinement; renders of the pool.
  `loop`       `fit`: the loop, outputs, checkpoints (`checkpoint`) and reports (`report`).
  `evaluate`   a scene's PSNR and SSIM on a capture's views (`python -m lgs_jax eval`).
  `camera_opt` the training views' pose deltas (`Settings.pose_opt`, gsplat's --pose_opt).
  `color_opt`  an affine colour correction per training view (`Settings.color_opt`).
  `bilateral_grid` a bilateral grid of colour maps per training view (`Settings.bilateral_grid`,
               gsplat's --use_bilateral_grid).
  `appearance` appearance embeddings: per-Gaussian features, per-view embeddings and the
               head they share (`Settings.app_opt`, gsplat's --app_opt).
  `view_params` the views' own parameters above as one state, their rows and updates.
  `data`       a capture made ready for `fit` (one or several image sizes), the view order.
"""

from .checkpoint import run_dir_problem
from .evaluate import evaluate
from .loop import fit
from .losses import loss_fn, psnr, ssim
from .optim import optimizer
from .pool import Pool, active_gaussians, from_gaussians, render_gaussians, sh_mask
from .settings import Settings, Setup
from .strategy import DefaultStrategy, MCMCStrategy, StepInfo, Strategy

__all__ = ["DefaultStrategy", "MCMCStrategy", "Pool", "Settings", "Setup", "StepInfo",
           "Strategy", "active_gaussians", "evaluate", "fit", "from_gaussians", "loss_fn",
           "optimizer", "psnr", "render_gaussians", "run_dir_problem", "sh_mask", "ssim"]
