"""SSIM and its gradient as two fused Pallas Triton kernels (the SSIM of `losses`, whose module
docstring has the equations; `losses.ssim` runs these on GPUs).

The images are (H, W, C), read as (H, W·C) planes: pixel x's channel c is column x·C + c, so a
horizontal tap of the window moves a column by C and every column is one independent output.

Forward (`forward_kernel`): one program per block of BLOCK_COLS columns and `block_rows` output
rows, one column per lane. It sweeps its block's rows top to bottom from RADIUS rows above to
RADIUS rows below. For each input row it blurs a, b, a², b², ab horizontally (2·RADIUS + 1 taps,
each a masked load at a shifted column: zero outside the image, the window's zero padding) and
keeps the last 2·RADIUS + 1 such rows in registers (a ring carried by the loop); once the ring
is full each new row completes one output row, whose vertical blur is the ring's weighted sum.
From the five blurred maps it forms the SSIM map s, adds the counted pixels' s into the
program's per-column sums (the mean: the sums of all programs, reduced afterwards by jnp.sum in
a fixed order; no atomics), and, when the gradient is wanted, stores the four per-pixel partial
maps of the mean (with g the mean's weight of a pixel, 1/N where counted, 0 elsewhere)

    d_μa = 2 g s (μ_b (1/A − 1/B) − μ_a/C + μ_a/D),  d_μb = the same with a and b swapped,
    d_var = −g s / D,  d_cov = 2 g s / B.

Backward (`backward_kernel`): the same sweep over the four partial maps (the adjoint of a
zero-padded correlation with a symmetric window is that correlation), then per pixel

    ∂/∂a = ct·(w * d_μa + 2a·(w * d_var) + b·(w * d_cov)),  ∂/∂b likewise with a and b swapped.

Each program's sweep reads 2·RADIUS rows more than it writes; its loads are L1/L2 hits of rows
its neighbours read too. Float32 or float64 arithmetic (the images' dtype, at least float32).
In interpret mode (tests, on the CPU) the masked loads and stores index with arrays, so that a
tap outside the image is masked rather than clamped.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as pl_triton

BLOCK_COLS = 64  # columns per program (a power of two): one per lane
ROW_BLOCKS = (32, 16, 8)  # output rows per program, the largest giving MIN_PROGRAMS programs
MIN_PROGRAMS = 256  # about two per SM of an H100: a small image in short blocks fills the GPU
WARPS = BLOCK_COLS // 32


def block_rows(h: int, wc: int) -> int:
    """Output rows per program for an (h, wc) plane: the largest of ROW_BLOCKS whose grid has
    at least MIN_PROGRAMS programs, else the smallest. A program sweeps 2·RADIUS rows more than
    it writes, so long blocks waste less; but each row of its sweep waits on the one before,
    and a small image in long blocks leaves most of the GPU idle."""
    cols = -(-wc // BLOCK_COLS)
    return next((r for r in ROW_BLOCKS if cols * -(-h // r) >= MIN_PROGRAMS), ROW_BLOCKS[-1])


@dataclasses.dataclass(frozen=True)
class _Static:
    """What the kernels bake in: the 1D window (2·RADIUS + 1 taps), C1 and C2, whether the
    border is left out of the mean ("valid"), the (H, W·C) plane and the channel count."""

    window: tuple[float, ...]
    c1: float
    c2: float
    valid: bool
    shape: tuple[int, int]
    channels: int
    rows: int  # output rows per program (`block_rows`)

    @property
    def radius(self) -> int:
        return (len(self.window) - 1) // 2

    @property
    def counted(self) -> int:
        """N, the pixels (times channels) of the mean."""
        h, wc = self.shape
        if not self.valid:
            return h * wc
        r = self.radius
        return max(h - 2 * r, 0) * max(wc - 2 * r * self.channels, 0)

    def grid(self):
        h, wc = self.shape
        return pl.cdiv(wc, BLOCK_COLS), pl.cdiv(h, self.rows)


def _columns():
    return pl.program_id(0) * BLOCK_COLS + lax.iota(jnp.int32, BLOCK_COLS)


def _horizontal(refs, products, r, cols, st: _Static):
    """Σ_k w_k · products(*[ref[r, cols + (k − RADIUS)·C] for ref in refs]): the horizontal
    blur of each product map on input row r, zero outside the image."""
    h, wc = st.shape
    acc = None
    for k, wk in enumerate(st.window):
        cc = cols + (k - st.radius) * st.channels
        mask = (r >= 0) & (r < h) & (cc >= 0) & (cc < wc)
        terms = products(*[pl_triton.load(ref.at[r, cc], mask=mask, other=0) for ref in refs])
        acc = ([wk * t for t in terms] if acc is None else
               [s + wk * t for s, t in zip(acc, terms)])
    return acc


def _sweep(row_blur, emit, n_maps: int, acc, dt, st: _Static):
    """Sweep the program's rows (module docstring): `row_blur(r)` gives the n_maps horizontal
    blurs of input row r; `emit(row, vertical blurs, acc)` gets each output row's n_maps
    blurred values and returns the new `acc`. Returns the last `acc`."""
    span = 2 * st.radius
    r0 = pl.program_id(1) * st.rows

    def step(i, carry, out: bool):
        ring, acc = carry
        window = ring + (tuple(row_blur(r0 - st.radius + i)),)
        if out:
            vertical = [functools.reduce(lambda x, y: x + y,
                                         [wk * rows[m] for wk, rows in zip(st.window, window)])
                        for m in range(n_maps)]
            acc = emit(r0 + i - span, vertical, acc)
        return window[1:], acc

    zero = jnp.zeros((BLOCK_COLS,), dt)
    carry = lax.fori_loop(0, span, functools.partial(step, out=False),
                          (((zero,) * n_maps,) * span, acc))
    return lax.fori_loop(span, span + st.rows, functools.partial(step, out=True), carry)[1]


def _ssim_terms(vertical, st: _Static):
    """(s, A, B, C, D) of the blurred μ_a, μ_b, w * a², w * b², w * ab."""
    mu_a, mu_b, aa, bb, ab = vertical
    big_a, big_b = 2 * mu_a * mu_b + st.c1, 2 * (ab - mu_a * mu_b) + st.c2
    big_c = mu_a * mu_a + mu_b * mu_b + st.c1
    big_d = (aa - mu_a * mu_a) + (bb - mu_b * mu_b) + st.c2
    return big_a * big_b / (big_c * big_d), big_a, big_b, big_c, big_d


def _counted(row, cols, st: _Static):
    """Whether output (row, cols) count in the mean."""
    h, wc = st.shape
    if not st.valid:
        return (row < h) & (cols < wc)
    r, border = st.radius, st.radius * st.channels
    return (row >= r) & (row < h - r) & (cols >= border) & (cols < wc - border)


def forward_kernel(a_ref, b_ref, sums_ref, *partial_refs, st: _Static):
    """Per-column sums of the counted SSIM over the program's rows (sums_ref[program]) and,
    with `partial_refs`, the partial maps d_μa, d_μb, d_var, d_cov (module docstring)."""
    dt = sums_ref.dtype
    h, wc = st.shape
    cols = _columns()
    inv_n = 1.0 / st.counted

    def row_blur(r):
        return _horizontal((a_ref, b_ref), lambda a, b: (a, b, a * a, b * b, a * b), r, cols,
                           st)

    def emit(row, vertical, acc):
        s, big_a, big_b, big_c, big_d = _ssim_terms(vertical, st)
        counted = _counted(row, cols, st)
        acc = acc + jnp.where(counted, s, 0)
        if partial_refs:
            mu_a, mu_b = vertical[:2]
            gs = jnp.where(counted, inv_n * s, 0)
            common = 1 / big_a - 1 / big_b
            maps = (2 * gs * (mu_b * common - mu_a / big_c + mu_a / big_d),
                    2 * gs * (mu_a * common - mu_b / big_c + mu_b / big_d),
                    -gs / big_d, 2 * gs / big_b)
            inside = (row < h) & (cols < wc)
            for ref, x in zip(partial_refs, maps):
                pl_triton.store(ref.at[row, cols], x, mask=inside)
        return acc

    sums = _sweep(row_blur, emit, 5, jnp.zeros((BLOCK_COLS,), dt), dt, st)
    sums_ref[pl.program_id(1) * pl.num_programs(0) + pl.program_id(0), :] = sums


def backward_kernel(ct_ref, a_ref, b_ref, mu_a_ref, mu_b_ref, var_ref, cov_ref, da_ref, db_ref,
                    *, st: _Static):
    """∂/∂a and ∂/∂b of ct · mean SSIM from the forward's partial maps (module docstring)."""
    h, wc = st.shape
    cols = _columns()
    ct = ct_ref[0]

    def row_blur(r):
        return _horizontal((mu_a_ref, mu_b_ref, var_ref, cov_ref), lambda *m: m, r, cols, st)

    def emit(row, vertical, acc):
        bm_a, bm_b, bv, bc = vertical
        inside = (row < h) & (cols < wc)
        a = pl_triton.load(a_ref.at[row, cols], mask=inside, other=0)
        b = pl_triton.load(b_ref.at[row, cols], mask=inside, other=0)
        pl_triton.store(da_ref.at[row, cols], ct * (bm_a + 2 * a * bv + b * bc), mask=inside)
        pl_triton.store(db_ref.at[row, cols], ct * (bm_b + 2 * b * bv + a * bc), mask=inside)
        return acc

    _sweep(row_blur, emit, 4, (), da_ref.dtype, st)


def _call(kernel, st: _Static, out_shape, interpret: bool, name: str):
    return pl.pallas_call(
        functools.partial(kernel, st=st), out_shape=out_shape, grid=st.grid(),
        compiler_params=pl_triton.CompilerParams(num_warps=WARPS, num_stages=1),
        interpret=interpret, name=name)


def _forward(a, b, st: _Static, partials: bool, interpret: bool):
    """(mean SSIM, the four partial maps or ()) of (H, W·C) planes of the kernels' dtype."""
    cols, rows = st.grid()
    sums = jax.ShapeDtypeStruct((cols * rows, BLOCK_COLS), a.dtype)
    plane = jax.ShapeDtypeStruct(a.shape, a.dtype)
    outs = _call(forward_kernel, st, [sums] + [plane] * (4 * partials), interpret,
                 "ssim_forward")(a, b)
    return jnp.sum(outs[0]) / st.counted, tuple(outs[1:])


def _static(a, window, data_range: float, padding: str, rows: int | None) -> _Static:
    h, w, c = a.shape
    return _Static(tuple(float(x) for x in window), (0.01 * data_range) ** 2,
                   (0.03 * data_range) ** 2, padding == "valid", (h, w * c), c,
                   rows or block_rows(h, w * c))


def _planes(a, b):
    dt = jnp.promote_types(jnp.result_type(a, b), jnp.float32)
    h, w, c = a.shape
    return a.reshape(h, w * c).astype(dt), b.reshape(h, w * c).astype(dt)


@functools.partial(jax.custom_vjp, nondiff_argnums=(2, 3, 4, 5, 6))
def _ssim(a, b, window, data_range, padding, interpret, rows):
    return _forward(*_planes(a, b), _static(a, window, data_range, padding, rows), False,
                    interpret)[0]


def _ssim_fwd(a, b, window, data_range, padding, interpret, rows):
    pa, pb = _planes(a, b)
    mean, partials = _forward(pa, pb, _static(a, window, data_range, padding, rows), True,
                              interpret)
    return mean, (a, b, pa, pb, partials)


def _ssim_bwd(window, data_range, padding, interpret, rows, res, ct):
    a, b, pa, pb, partials = res
    st = _static(a, window, data_range, padding, rows)
    plane = jax.ShapeDtypeStruct(pa.shape, pa.dtype)
    da, db = _call(backward_kernel, st, [plane, plane], interpret, "ssim_backward")(
        jnp.reshape(ct, (1,)).astype(pa.dtype), pa, pb, *partials)
    return da.reshape(a.shape).astype(a.dtype), db.reshape(b.shape).astype(b.dtype)


_ssim.defvjp(_ssim_fwd, _ssim_bwd)


def ssim(a, b, window: tuple[float, ...], data_range: float, padding: str, interpret: bool,
         rows: int | None = None):
    """Mean SSIM of two (H, W, C) images with the 1D `window` (odd length, symmetric),
    `padding` "same" or "valid" (losses module docstring; "valid" needs an image larger than the
    window), by the kernels (interpret mode, or
    lowered for the GPU); differentiable through the backward kernel. `rows`: output rows per
    program (None: `block_rows` of the image's size); the gradients do not depend on it, the
    value only through the grouping of its sum."""
    if a.ndim != 3 or a.shape != b.shape:
        raise ValueError(f"ssim: expected two (H, W, C) images of one shape, got {a.shape} and "
                         f"{b.shape}")
    if not _static(a, window, data_range, padding, rows).counted:
        raise ValueError(f"ssim: padding='valid' counts no pixel of a {a.shape[0]}x{a.shape[1]} "
                         f"image (the window's {len(window) - 1}-pixel border is left out)")
    return _ssim(a, b, tuple(float(x) for x in window), float(data_range), padding, interpret,
                 rows)
