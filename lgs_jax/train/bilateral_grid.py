"""Per-view bilateral grids (`Recipe.bilateral_grid`, `fit --bilateral-grid`): gsplat
simple_trainer's `--use_bilateral_grid` (Wang et al. 2024, "Bilateral Guided Radiance Field
Processing", gsplat's examples/lib_bilagrid.py), for photos whose camera processing (tone
curves, local exposure, white balance) varies over the image and between photos: a colour map
per training view that varies with the pixel's place and brightness, where `color_opt`'s is one
affine map per photo.

Each training view has a grid of 3x4 affine colour maps, X x Y = 16 x 16 cells over the image
and L = 8 over the brightness (gsplat's shape), stored as its difference P from the identity
map (gsplat stores I + P), zero at the start. A pixel in row i, column j of an H x W render,
colour C, takes the grid's trilinear interpolation at

    (x, y, z) = (u·(X − 1), v·(Y − 1), clip(γ, 0, 1)·(L − 1)),  u = (j + ½)/W, v = (i + ½)/H,
    γ = 0.299 r + 0.587 g + 0.114 b

(torch's grid_sample with align_corners=True and border padding, as gsplat slices it), the
weights the hat functions h(t − k) = max(0, 1 − |t − k|) of each axis; with (ΔM | Δt) = slice(P)
its colour becomes

    C' = C + ΔM C + Δt       (`corrected`; P = 0 gives C to the bit).

The loss adds tv_weight · TV(P) over every view's grid (gsplat's total_variation_loss: along each
grid axis the mean squared difference of neighbouring cells, summed over the three axes). Adam
(ε = 1e-15) at lr_grid · sqrt(batch), warmed up linearly from 1% over the first 1000 steps and
decaying exponentially to 1% over the run (gsplat's ChainedScheduler of LinearLR and
ExponentialLR). After each update the grids are centred over the training views (`project`, as
`color_opt` centres its maps; gsplat does not): the scene keeps the views' average appearance
and held-out views, rendered without a grid, render at it.

Deterministic on GPUs: the slice is dense contractions with the hat weights (dots, whose
gradients are dots), no gather whose gradient would be a scatter-add; it runs over blocks of
rows (`lax.map`, each block recomputed in the backward) so that no (H, W, 96) array is held
whole.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..parallel import to_host
from .optim import torch_adam

X, Y, L = 16, 16, 8  # cells along the image's width, its height, and the brightness
COEFFS = 12  # a 3x4 affine map (M | t), row-major: coefficient 4r + c
SIZE = COEFFS * L * Y * X  # per view (`view_params`)
GRAY = (0.299, 0.587, 0.114)
BLOCKS = 8  # row blocks of a slice
WARMUP = 1000  # steps of the linear warm-up
HIGHEST = jax.lax.Precision.HIGHEST


def enabled(recipe) -> bool:
    return recipe.bilateral_grid


def _hat(t, n: int):
    """(..., n) weights max(0, 1 − |t − k|) of k = 0..n−1 for positions t (...)."""
    return jnp.maximum(0, 1 - jnp.abs(t[..., None] - jnp.arange(n, dtype=t.dtype)))


def coefficients(image, p):
    """(H, W, 12) affine maps (ΔM | Δt) sliced from grid p (SIZE,) at each pixel of `image`
    (H, W, 3) (module docstring)."""
    h, w, _ = image.shape
    dt = image.dtype
    grid = jnp.reshape(p.astype(dt), (COEFFS, L, Y, X))
    wx = _hat((jnp.arange(w, dtype=dt) + 0.5) / w * (X - 1), X)  # (W, X)
    wy = _hat((jnp.arange(h, dtype=dt) + 0.5) / h * (Y - 1), Y)  # (H, Y)
    gray = jnp.clip(image @ jnp.asarray(GRAY, dt), 0, 1) * (L - 1)
    across = jnp.einsum("jx,kzyx->yjkz", wx, grid, precision=HIGHEST)  # (Y, W, 12, L)
    rows = -(-h // BLOCKS)
    pad = rows * BLOCKS - h
    wy = jnp.pad(wy, ((0, pad), (0, 0))).reshape(BLOCKS, rows, Y)
    wz = _hat(jnp.pad(gray, ((0, pad), (0, 0))), L).reshape(BLOCKS, rows, w, L)

    @jax.checkpoint
    def block(args):
        wy_b, wz_b = args
        at_rows = jnp.einsum("iy,yjkz->ijkz", wy_b, across, precision=HIGHEST)
        return jnp.einsum("ijz,ijkz->ijk", wz_b, at_rows, precision=HIGHEST)

    return jax.lax.map(block, (wy, wz)).reshape(rows * BLOCKS, w, COEFFS)[:h]


def corrected(image, p):
    """`image` (H, W, 3) as a view with grid p (SIZE,) sees it: C + ΔM C + Δt per pixel."""
    a = coefficients(image, p).reshape(image.shape[:2] + (3, 4))
    change = jnp.einsum("hwij,hwj->hwi", a[..., :3], image, precision=HIGHEST)
    return image + change + a[..., 3]


def total_variation(p):
    """TV of the grids p (views, SIZE) (module docstring)."""
    g = jnp.reshape(p, (-1, COEFFS, L, Y, X))
    return sum(jnp.mean(jnp.diff(g, axis=axis) ** 2) for axis in (2, 3, 4))


def regularizer(recipe, p):
    """The loss's term of the grids p (views, SIZE): tv_weight · TV(p)."""
    return recipe.grid_tv * total_variation(p)


def schedule(recipe, steps: int):
    """The grids' learning rate at update s (module docstring)."""
    lr = recipe.lr_grid * math.sqrt(recipe.batch)
    decay = optax.exponential_decay(1.0, max(steps, 1), 0.01)
    return lambda s: lr * (0.01 + 0.99 * jnp.minimum(s, WARMUP) / WARMUP) * decay(s)


def optimizer(recipe, steps: int) -> optax.GradientTransformation:
    """The grids' optimizer (module docstring)."""
    return torch_adam(schedule(recipe, steps), 0.0, eps=1e-15)


def save(path: str, p, names) -> None:
    """bilateral_grids.npz: `grids` (views, 12, L, Y, X), each view's maps I + P in gsplat's
    layout (its BilateralGrid.grids), and `names`, the views' names."""
    grids = np.array(to_host(p), np.float32).reshape(-1, COEFFS, L, Y, X)
    grids[:, [0, 5, 10]] += 1  # (M | t) = I + P: the diagonal of M
    np.savez(path, grids=grids, names=np.asarray(names))


def project(p):
    """The grids (views, SIZE) centred over the views (module docstring)."""
    return p - jnp.mean(p, axis=0)
