"""The backward walk's two quotients by 1 − α, as the Mosaic GPU backward kernel computes them
on the GPU (`backward.walk_step`'s `quotients`): one reciprocal, two products.

    T_k = T_{k+1} · r,   (S·ḡ + ḡ_T·T_N)/(1 − α) = (S·ḡ + ḡ_T·T_N) · r,   r = rcp(1 − α)

`x / y` in a Mosaic GPU kernel compiles to PTX `div.full.f32`, which on Hopper is the same
`MUFU.RCP` and `FMUL` behind two range tests and three predicated rescalings per quotient
(|y| > 2^126: operands · 1/4; |y| < 2^-126: · 2^24), 11 SASS instructions for the two quotients
of one pixel. Here 1 − α lies in [1 − cap, 1] (α <= cap < 1; a miss is α = 0), where neither
rescaling applies, so `rcp.approx.ftz.f32` and two multiplies that PTX may not contract
(`mul.rn`, as LLVM writes an `fmul` without `contract`) give `div.full`'s bits in 3
instructions per pixel (`scripts/kernel_sass.py` shows the machine code). Inline Mosaic GPU
code: GPU only; interpret mode and the other backends divide (`reference`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax.experimental.mosaic.gpu import fragmented_array as mgpu_fa
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, nvvm, vector

from .inline import element


def of(interpret: bool, dtype):
    """`backward.walk_step`'s quotients for a Mosaic GPU kernel: `quotients` on the GPU in
    float32, None (`/`) in interpret mode or float64."""
    return None if interpret or dtype != jnp.float32 else quotients


def reference(denominator, numerators):
    """numerators[i] / denominator by division: what `quotients` computes, to the bit on its
    domain (module docstring)."""
    return tuple(x / denominator for x in numerators)


def quotients(denominator, numerators):
    """numerators[i] / denominator for float32 lane vectors of one block (Mosaic GPU's strided
    layout of a (pixels,) array, as `steps.backward_lanes` makes them), denominator in
    [2^-126, 2^126] (module docstring): one reciprocal per element, then the products."""
    pixels = denominator.shape[0]
    layout = plgpu.Layout.WG_STRIDED((pixels,), vec_size=pixels // 128)

    @plgpu.inline_mgpu(
        arg_types=(layout,) * (1 + len(numerators)),
        return_type=tuple(plgpu.ShapeDtypeStruct((pixels,), x.dtype, layout=layout)
                          for x in numerators))
    def divide(_, den, *nums):
        vec_type = ir.VectorType(den.registers.flat[0].type)
        width = vec_type.shape[0]
        recips = [nvvm.rcp_approx_ftz_f(element(den.registers.flat[0], e))
                  for e in range(width)]
        out = []
        for num in nums:
            products = [arith.mulf(element(num.registers.flat[0], e), r)
                        for e, r in enumerate(recips)]
            out.append(mgpu_fa.FragmentedArray(
                _registers=np.array([vector.from_elements(vec_type, products)], dtype=object),
                _layout=den.layout, _is_signed=None))
        return tuple(out)

    return divide(denominator, *numerators)
