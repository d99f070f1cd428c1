"""Per-view colour correction (`Recipe.color_opt`, `fit --color-opt`), for captures whose
exposure or white balance changes from view to view (a phone's automatic exposure): an affine
colour transform per training view, the lightest form of gsplat simple_trainer's appearance
options (its `--app_opt` embeddings and `--use_bilateral_grid`, which vary over the image).

Each training view i has a 12-vector p_i = (A_i, b_i), A_i a 3x3 matrix (row-major) and b_i a
colour, zero at the start. The view's render C (each pixel's colour after compositing over the
background, a column vector) is compared with its photo as

    C'_i = C + A_i C + b_i     (`corrected`; p_i = 0 gives C to the bit).

After each update the corrections are centred over the training views, p_i ← p_i − mean_j p_j
(`project`): a projected gradient step onto corrections of mean zero, so that the scene keeps
the views' average appearance (the corrections cannot drift together while the scene's colours
drift the other way) and held-out views, which have no correction, render at it. The centring
moves every view's correction by the mean of the step's change, small beside the change of the
step's own views (their share of the views), and adds no gradient to the other views. The
corrections take their own Adam (torch's defaults, as `camera_opt`) at rate lr_color ·
sqrt(batch), with L2 weight decay color_reg added to the gradient.
"""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..parallel import to_host
from .optim import torch_adam

SIZE = 12  # (A row-major, b) per view (`view_params`)
HIGHEST = jax.lax.Precision.HIGHEST


def enabled(recipe) -> bool:
    return recipe.color_opt


def corrected(image, p):
    """`image` (H, W, 3) as view p (12,) sees it: C + A C + b per pixel (module docstring)."""
    a = jnp.reshape(p[:9], (3, 3)).astype(image.dtype)
    change = jnp.einsum("ij,hwj->hwi", a, image, precision=HIGHEST)
    return image + change + p[9:].astype(image.dtype)


def optimizer(recipe, steps: int) -> optax.GradientTransformation:
    """The corrections' optimizer (module docstring; constant over the `steps`)."""
    return torch_adam(recipe.lr_color * math.sqrt(recipe.batch), recipe.color_reg)


def project(p):
    """The corrections (views, 12) centred over the views (module docstring)."""
    return p - jnp.mean(p, axis=0)


def save(path: str, corrections, names) -> None:
    """colors.json: each training view's colour correction (`names`, the same order) as the
    affine map of render colours to its photo's, C' = matrix · C + offset (matrix = I + A,
    offset = b)."""
    p = to_host(corrections).astype(np.float64)
    rows = [dict(img_name=n, matrix=(np.eye(3) + q[:9].reshape(3, 3)).tolist(),
                 offset=q[9:].tolist()) for n, q in zip(names, p)]
    with open(path, "w") as f:
        json.dump(rows, f, indent=1)
