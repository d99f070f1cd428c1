"""Real spherical harmonics up to degree 3, with the 3DGS / gsplat basis constants."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
      0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
      -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def sh_basis_terms(x, y, z, num_bases: int):
    """The first `num_bases` real SH basis functions at unit directions (x, y, z) (arrays of
    any one shape), as a list ordered as the INRIA coefficients (degree-major). The colour is
    max(Σ_k basis_k·sh_k + 0.5, 0) per channel (docs/conventions.md, "Colour";
    lgs_jax.projection)."""
    out = [C0 * jnp.ones_like(x)]
    if num_bases > 1:
        out += [-C1 * y, C1 * z, -C1 * x]
    if num_bases > 4:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [C2[0] * xy, C2[1] * yz, C2[2] * (2.0 * zz - xx - yy), C2[3] * xz,
                C2[4] * (xx - yy)]
    if num_bases > 9:
        out += [C3[0] * y * (3.0 * xx - yy), C3[1] * xy * z, C3[2] * y * (4.0 * zz - xx - yy),
                C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy), C3[4] * x * (4.0 * zz - xx - yy),
                C3[5] * z * (xx - yy), C3[6] * x * (xx - 3.0 * yy)]
    return out


def _masked(sh, keep, k: int, c: int):
    """Coefficient column sh[:, k, c] where `keep`, else 0."""
    return jnp.where(keep, sh[:, k, c], 0.0)


@jax.custom_vjp
def sh_sums(basis, sh, keep):
    """Σ_k basis_k · sh'[:, k, c] for each channel c: a list of three (N,) columns, from the
    basis terms (`sh_basis_terms`' list of K (N,) columns) and the coefficients sh (N, K, 3),
    sh' = sh where `keep` (N,) holds and 0 elsewhere. The mask is applied per column: applied
    to the (N, K, 3) array, XLA stored it in a pass of its own.

    Its vjp: ∂L/∂sh[:, k, c] = basis_k · ∂L/∂s_c (0 where not `keep`), one broadcast product
    of the basis stacked (N, K) and the cotangents stacked (N, 3), both stored first (an
    optimization barrier); and ∂L/∂basis_k = Σ_c ∂L/∂s_c · sh'[:, k, c] (channels summed last
    to first, as autodiff of the sums did). Differentiated as K·3 separate products, the
    (N, K, 3) cotangent was a 48-operand concatenate of them, which XLA's GPU loop emitter
    computes with a branch per element, so every warp ran most of the 48 products one after
    another; with the products stored as 48 columns first, the columns and the stack were live
    at once. The broadcast product is faster and smaller than both, with the same bits. At SH
    degree 0 (K = 1) the three products are stacked as they are: XLA's concatenate emitter,
    which it uses up to four operands, writes them without branches, and storing the
    cotangents first added three passes."""
    return [sum(b * _masked(sh, keep, k, c) for k, b in enumerate(basis)) for c in range(3)]


def _sums_fwd(basis, sh, keep):
    return sh_sums(basis, sh, keep), (basis, sh, keep)


def _sums_bwd(res, cts):
    basis, sh, keep = res
    if len(basis) == 1:  # three products: XLA's concatenate emitter writes them branch-free
        d_sh = jnp.stack([basis[0] * ct for ct in cts], -1)[:, None, :]
    else:
        stacked, ct = lax.optimization_barrier((jnp.stack(basis, -1), jnp.stack(cts, -1)))
        d_sh = stacked[:, :, None] * ct[:, None, :]
    d_basis = [functools.reduce(lambda acc, c: acc + cts[c] * _masked(sh, keep, k, c), (1, 0),
                                cts[2] * _masked(sh, keep, k, 2)) for k in range(len(basis))]
    return d_basis, jnp.where(keep[:, None, None], d_sh, 0.0), None


sh_sums.defvjp(_sums_fwd, _sums_bwd)
