"""Camera pose optimization (`Recipe.pose_opt`, `fit --pose-opt`): gsplat simple_trainer's
`--pose_opt` (its CameraOptModule), for captures whose poses are off by a little.

Each training view i has a 9-vector δ_i = (t, r) (zero at the start): t a translation and r a
change of a 6-D rotation representation. Its camera-to-world pose C_i becomes C_i · D(δ_i),

    D(δ) = [[R(e + r), t], [0, 1]],  e = (1, 0, 0, 0, 1, 0),

R(a) the Gram-Schmidt rotation of the 6-D representation a = (a1, a2) (Zhou et al. 2019, as
PyTorch3D's rotation_6d_to_matrix: rows b1 = a1/|a1|, b2 = (a2 − (b1·a2) b1)/|·|, b3 = b1 × b2),
so the world-to-camera matrix `viewmat` becomes D(δ)⁻¹ · viewmat, D⁻¹ = [[Rᵀ, −Rᵀ t], [0, 1]]
(`adjusted`). At δ = 0, R = I and t = 0 exactly, so the render is the unadjusted one to the bit.
The deltas are a part of the views' own parameters (`view_params`) with their own Adam (β =
0.9, 0.999, ε = 1e-8, torch's defaults) at rate lr_pose · sqrt(batch), L2 weight decay pose_reg
added to the gradient (torch's `weight_decay`), as gsplat does. Held-out views keep their
poses (gsplat evaluates them so too).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import optax

from ..scene import Camera
from .optim import torch_adam

IDENTITY_6D = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
HIGHEST = jax.lax.Precision.HIGHEST


def rotation_6d(a):
    """(..., 3, 3) rotations (rows b1, b2, b3) of the 6-D representations a (..., 6)."""
    a1, a2 = a[..., :3], a[..., 3:]
    b1 = a1 / jnp.linalg.norm(a1, axis=-1, keepdims=True)
    b2 = a2 - jnp.sum(b1 * a2, -1, keepdims=True) * b1
    b2 = b2 / jnp.linalg.norm(b2, axis=-1, keepdims=True)
    return jnp.stack([b1, b2, jnp.cross(b1, b2)], -2)


def adjusted(cams: Camera, deltas) -> Camera:
    """`cams` (a batch, viewmat (B, 4, 4)) with each pose moved by its delta (B, 9) (module
    docstring): viewmat ← D(δ)⁻¹ · viewmat."""
    dt = cams.viewmat.dtype
    deltas = deltas.astype(dt)
    rot = rotation_6d(deltas[..., 3:] + jnp.asarray(IDENTITY_6D, dt))
    rot_t = jnp.swapaxes(rot, -1, -2)
    shift = -jnp.einsum("...ij,...j->...i", rot_t, deltas[..., :3], precision=HIGHEST)
    inverse = jnp.concatenate([jnp.concatenate([rot_t, shift[..., None]], -1),
                               jnp.broadcast_to(jnp.asarray([0, 0, 0, 1], dt),
                                                rot.shape[:-2] + (1, 4))], -2)
    return dataclasses.replace(cams, viewmat=jnp.einsum("...ij,...jk->...ik", inverse,
                                                        cams.viewmat, precision=HIGHEST))


SIZE = 9  # the delta's length (`view_params`)


def enabled(recipe) -> bool:
    return recipe.pose_opt


def optimizer(recipe, steps: int) -> optax.GradientTransformation:
    """The deltas' optimizer (module docstring; constant over the `steps`)."""
    return torch_adam(recipe.lr_pose * math.sqrt(recipe.batch), recipe.pose_reg)


def project(deltas):
    """The deltas after an update (`view_params.update`): unchanged."""
    return deltas
