"""The Pallas backends, `pallas` (Local-GS) and `pallas_vanilla` (the original 3DGS
rasterizer): the rasterization stage as Pallas kernels, forward and backward.

Modules, each kernel beside its plain-jnp reference:
  backend         `forward`, `gradients`, `rasterize` (their custom_vjp), the `Backend`s.
  plan            `plan`: lowering, interpret mode, block sizes, output layouts.
  steps           the per-pair arithmetic every kernel shares (records, α, blend, backward step).
  mosaic_forward  the Local-GS and vanilla forward kernels on Mosaic GPU (the GPU path).
  mosaic_backward the backward kernel on Mosaic GPU.
  triton          the same kernels on Pallas Triton (interpret mode's path) and their records.
  staging         pair records built inside the Mosaic GPU kernels (`reference`: in jnp).
  warp_lists      per-warp pair lists of the compacted forward (interpret-mode branch in jnp).
  rows            the backward's per-pair row reduction (`reference`: jnp sums).
  gaussian_grads  per-Gaussian sums of the backward's rows (`sums` kernel, `reference`).
  table           the per-Gaussian table kernel (`reference`: `pairs.gaussian_table`).
  segments        the split backward's segments and their entering carries.
  order           longest-first block order (`reference`: the exact argsort).
  inline, quotients  inline Mosaic GPU helpers; the backward's quotients (`reference`).
The plain-jnp counterpart of the whole rasterization is the `tiles` backend (same masks, same
hoisted arithmetic, same blending, same backward walk) and `reference` (per-pixel semantics).
"""

# The first pallas_call imports this module lazily, and its import adds to JAX's tracing
# context: every program traced before it (a run's start-up programs) would miss its jit cache
# once and be traced again. Imported with the backend, the context is the same from the start.
import jax.experimental.pallas.fuser  # noqa: F401

from .backend import LOCALGS, VANILLA, PallasStats, forward, gradients, rasterize
from .plan import Plan, plan

__all__ = ["LOCALGS", "VANILLA", "PallasStats", "Plan", "forward", "gradients", "plan",
           "rasterize"]
