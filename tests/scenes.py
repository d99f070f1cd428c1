"""Random and adversarial test scenes with fixed shapes (values vary, shapes never do, so a
hypothesis run compiles each function once)."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import strategies as st

import lgs_jax
from lgs_jax.config import ALPHA_MIN
from lgs_jax.projection import EPS2D, Projected

N = 32  # Gaussians per test scene (fixed: no recompiles)
W, H = 40, 24  # image size: not a multiple of 16, so edge tiles are partial
CAPACITY = 256  # pair buffer of every test render: >= N x the 3x2 tiles of a W x H image

KINDS = ("normal", "needle", "huge_far", "tiny", "behind", "faint", "opaque", "layers", "invalid")


def camera(width=W, height=H, dtype=np.float32, yaw=0.0):
    """Camera at the origin looking down +z (OpenCV axes), optionally yawed."""
    c, s = np.cos(yaw), np.sin(yaw)
    view = np.eye(4)
    view[:3, :3] = [[c, 0, -s], [0, 1, 0], [s, 0, c]]
    f = 0.9 * width
    return lgs_jax.Camera(viewmat=view.astype(dtype), fx=dtype(f), fy=dtype(f),
                          cx=dtype(width / 2), cy=dtype(height / 2), width=width, height=height)


BACKGROUND = (0.2, 0.5, 0.9)


def render(g, cam, backend, config, bg=BACKGROUND):
    """Render a test scene with a fixed capacity (one compile per shape) and a coloured
    background (so background-weighting errors show)."""
    return lgs_jax.render(g, cam, background=np.asarray(bg, g.means.dtype), backend=backend,
                          config=config, capacity=CAPACITY)


def random_quats(rng, n):
    return rng.normal(size=(n, 4)) * rng.uniform(0.1, 3.0, size=(n, 1))  # not unit length


def scene(seed: int, kinds=KINDS, n=N, sh_bases=4, dtype=np.float64) -> lgs_jax.Gaussians:
    """A scene whose Gaussians are drawn from the listed adversarial kinds.

    normal: in view, moderate size. needle: one long axis, two ~1e-3 axes. huge_far: scales up to
    e^2 and centres far outside the image. tiny: sub-pixel. behind: z < near. faint: opacity within
    ±2% of 1/255. opaque: logit +inf. layers: many Gaussians stacked at one spot, depths ties
    included. invalid: NaN / inf / zero-quaternion rows.
    """
    rng = np.random.default_rng(seed)
    kind = rng.choice(kinds, size=n)
    z = rng.uniform(1.5, 6.0, n)
    means = np.stack([rng.uniform(-0.35, 0.35, n) * z * W / (0.9 * W),
                      rng.uniform(-0.35, 0.35, n) * z * H / (0.9 * W), z], -1)
    log_scales = rng.uniform(-3.5, -1.0, (n, 3))
    logit = rng.normal(0, 2, n)
    quats = random_quats(rng, n)
    sh = rng.normal(0, 0.5, (n, sh_bases, 3))
    for i, k in enumerate(kind):
        if k == "needle":
            log_scales[i] = [rng.uniform(-0.5, 1.0), -7.0, -7.0]
        elif k == "huge_far":
            log_scales[i] = rng.uniform(0.0, 2.0, 3)
            means[i, 0] += rng.choice([-1, 1]) * rng.uniform(5, 40)
        elif k == "tiny":
            log_scales[i] = rng.uniform(-9, -6, 3)
        elif k == "behind":
            means[i, 2] = rng.uniform(-2.0, 0.01)
        elif k == "faint":
            o = (1 / 255) * (1 + rng.uniform(-0.02, 0.02))
            logit[i] = np.log(o / (1 - o))
        elif k == "opaque":
            logit[i] = np.inf
        elif k == "layers":
            means[i] = [0.05, -0.03, 2.0 + 0.25 * rng.integers(0, 3)]
            logit[i] = rng.uniform(0, 4)
        elif k == "invalid":
            which = rng.integers(0, 4)
            if which == 0:
                means[i, rng.integers(0, 3)] = np.nan
            elif which == 1:
                quats[i] = 0.0
            elif which == 2:
                log_scales[i, 0] = np.inf
            else:
                means[i, 0] = -np.inf
    return lgs_jax.Gaussians(means=means.astype(dtype), quats=quats.astype(dtype),
                             log_scales=log_scales.astype(dtype),
                             logit_opacities=logit.astype(dtype), sh=sh.astype(dtype))


FIELDS = ("means", "quats", "log_scales", "logit_opacities", "sh")  # Gaussians' leaf order


def saturating(seed: int, n: int, dtype) -> lgs_jax.Gaussians:
    """Adversarial Gaussians behind and among a wall of large, nearly opaque ones (every other
    Gaussian): on a 32x32 image most pixels stop well before the end of their tile's list, after
    tens of pairs (the backward's walked rows and segments)."""
    g = scene(seed, kinds=("normal", "needle", "tiny", "opaque", "invalid"), n=n)
    rng = np.random.default_rng(seed)
    wall = np.arange(n) % 2 == 0
    means, log_scales, logit = (np.array(x) for x in (g.means, g.log_scales, g.logit_opacities))
    means[wall] = np.stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n),
                            rng.uniform(2.0, 4.0, n)], -1)[wall]
    log_scales[wall] = rng.uniform(-0.5, 0.5, (n, 3))[wall]
    logit[wall] = rng.uniform(2, 6, n)[wall]
    return cast(dataclasses.replace(g, means=means, log_scales=log_scales,
                                    logit_opacities=logit), dtype)


def half_walled(seed: int, n: int, dtype) -> lgs_jax.Gaussians:
    """Faint Gaussians (opacity 0.4-5%) filling a 16x16 image, a fifth of them replaced by
    nearly opaque ones over its top half: on `camera(16, 16)` with seed 0 and n = 700 the top
    half's pixels stop after 281-455 pairs, the bottom half's after 390 to all 700. So a
    half-tile forward block (the top) stops well before its whole-tile backward block does."""
    g = scene(seed, kinds=("normal",), n=n)
    rng = np.random.default_rng(seed)
    means = np.stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-1.2, 1.2, n),
                      rng.uniform(2.0, 4.0, n)], -1)
    log_scales, logit = rng.uniform(-0.3, 0.3, (n, 3)), rng.uniform(-5.5, -3, n)
    wall = np.arange(n) % 5 == 0
    means[wall] = np.stack([rng.uniform(-2, 2, n), rng.uniform(-1.7, -0.3, n),
                            rng.uniform(2.8, 3.2, n)], -1)[wall]
    log_scales[wall] = rng.uniform(-1.0, -0.5, (n, 3))[wall]
    logit[wall] = rng.uniform(0, 3, n)[wall]
    return cast(dataclasses.replace(g, means=means, log_scales=log_scales,
                                    logit_opacities=logit), dtype)


def cast(g: lgs_jax.Gaussians, dtype) -> lgs_jax.Gaussians:
    import jax

    return jax.tree.map(lambda x: np.asarray(x, dtype), g)


def float_arrays(lo, hi, n):
    """A hypothesis strategy for float64 arrays of fixed length n."""
    return st.lists(st.floats(lo, hi), min_size=n, max_size=n).map(np.asarray)


def projected_conics(dtype, log_kappa, theta, log_lmin, offset, angle, logit, edge=None,
                     width=64, height=48, edge_pixel=None):
    """Projected Gaussians with 2D covariance eigenvalues λmin (>= the 0.3 dilation) and
    λmin·κ, rotated by θ, centred `offset` px from the image centre.

    With `edge` (relative offsets ~1e-6), Gaussian m is instead placed so that a pixel centre near
    the image centre lies on its 1/255 ellipse (q = τ·(1 + edge[m])) in the direction `angle`:
    the float test there is a coin flip, which is where an unpadded box fails. `edge_pixel`
    (n, 2) integer (column, row) picks that pixel per Gaussian (default: the image centre)."""
    n = len(log_kappa)
    lmin = EPS2D + np.exp(log_lmin)
    lmax = lmin * np.exp(log_kappa)
    c, s = np.cos(theta), np.sin(theta)
    sxx, sxy, syy = c * c * lmax + s * s * lmin, c * s * (lmax - lmin), s * s * lmax + c * c * lmin
    cov = np.stack([sxx, sxy, syy], -1).astype(dtype)
    sxx, sxy, syy = (cov[:, i] for i in range(3))
    det = sxx * syy - sxy * sxy  # in dtype, as projection does
    with np.errstate(divide="ignore", invalid="ignore"):
        conic = np.stack([syy / det, -sxy / det, sxx / det], -1)
    mean = np.stack([width / 2 + offset * np.cos(angle), height / 2 + offset * np.sin(angle)], -1)
    opacity = np.asarray(jax.nn.sigmoid(logit.astype(dtype)))
    if edge is not None:
        q64 = np.stack([syy, -sxy, sxx], -1).astype(np.float64) / det.astype(np.float64)[:, None]
        v = np.stack([np.cos(angle), np.sin(angle)], -1)
        qv = q64[:, 0] * v[:, 0] ** 2 + 2 * q64[:, 1] * v[:, 0] * v[:, 1] + q64[:, 2] * v[:, 1] ** 2
        tau = 2 * np.log(np.maximum(255 * opacity.astype(np.float64), 1.0))
        r = np.sqrt(np.maximum(tau * (1 + edge), 0) / np.where(qv > 0, qv, 1.0))
        pix = (np.array([[width // 2, height // 2]]) if edge_pixel is None
               else np.asarray(edge_pixel)) + 0.5
        mean = np.where((qv > 0)[:, None], pix + r[:, None] * v, mean)
    valid = (det > 0) & np.all(np.isfinite(conic), -1) & (opacity >= dtype(ALPHA_MIN))
    return Projected(mean2d=jnp.asarray(mean, dtype), mean2d_lo=jnp.zeros((n, 2), dtype),
                     cov2d=jnp.asarray(cov),
                     conic=jnp.asarray(np.where(valid[:, None], conic, 1.0), dtype),
                     depth=jnp.ones(n, dtype), opacity=jnp.asarray(np.where(valid, opacity, 0)),
                     rgb=jnp.zeros((n, 3), dtype), valid=jnp.asarray(valid),
                     invalid=jnp.asarray(~valid))


@functools.partial(jax.jit, static_argnames="capacity")
def jit_render(g, cam, capacity=CAPACITY):
    """`lgs_jax.render` (default backend) under jit, the scene and camera as arguments: the
    tests that need a traced render share its programs (one per shape and capacity)."""
    return lgs_jax.render(g, cam, capacity=capacity)


@functools.partial(jax.jit, static_argnames="capacity")
def projected_bins(g, cam, capacity=CAPACITY):
    """(`project(g, cam)`, its `bin_gaussians` at `capacity`), jitted with the scene and camera
    as arguments: one compile per shape, where eager calls compile each operation."""
    from lgs_jax import binning
    from lgs_jax.projection import project

    p = project(g, cam)
    return p, binning.bin_gaussians(p, cam.width, cam.height, capacity)


@functools.partial(jax.jit, static_argnames="config")
def _kernel_forward(g, cam, config):
    """The Local-GS kernel's forward on a test scene, with what its backward needs."""
    from lgs_jax import binning
    from lgs_jax.backends import pallas
    from lgs_jax.projection import project

    p = project(g, cam)
    bins = binning.bin_gaussians(p, cam.width, cam.height, CAPACITY)
    plan = pallas.plan(config, vanilla=False, n_tiles=bins.tile_start.shape[0])
    state, stop_at, _, saved = pallas.forward(p, bins, None, cam.width, cam.height, plan)
    return p, bins, state, stop_at, saved


@functools.partial(jax.jit, static_argnames="config")
def _kernel_and_walk_rows(p, bins, cam, state, stop_at, saved, cot, config):
    """The backward kernel's pair rows and the plain-jnp walk's, from the same residuals."""
    from lgs_jax.backends import pallas, tiles
    from lgs_jax.backends.pallas import triton
    from lgs_jax.layout import tile_grid, tiled_image_to_tiles

    plan = pallas.plan(config, vanilla=False, n_tiles=bins.tile_start.shape[0])
    got = pallas.gradients(p, bins, None, cam.width, cam.height, plan, state.trans, stop_at,
                           saved, cot)
    # The walk reads XLA's masks and records (the Mosaic GPU kernels' `saved` are the Gaussian
    # ids and table they build them from), each pixel's stop pair (the forward may return each
    # block's: Plan.block_stops) and the colour's cotangent per tile (the forward may write an
    # image: Plan.image).
    masks, records, _ = triton.records(p, bins, tile_grid(cam.width, cam.height)[0], config)
    g_color = tiled_image_to_tiles(cot[0]) if plan.image else cot[0]
    want = tiles.gradients(p, bins, None, cam.width, cam.height, config, state.trans, saved[-1],
                           (masks if config.warp_cull else None,
                            records[:, :7] if config.hoist else None),
                           (g_color,) + tuple(cot[1:]))
    return got, want


def backward_kernel_and_walk(seed: int, config, dtype):
    """The Local-GS backward kernel's gradients (`pallas.gradients`) and those of its plain-jnp
    counterpart (`tiles.gradients`) on one test scene, from the same residuals (the kernel's
    forward: final T, stop pairs, masks, records) and random cotangents; numpy arrays. Both
    stages are jitted with the scene as an argument: one compile per (config, dtype)."""
    g = cast(scene(seed), dtype)
    cam = camera(dtype=dtype)
    p, bins, state, stop_at, saved = _kernel_forward(g, cam, config)
    rng = np.random.default_rng(seed % 2**16)
    cot = tuple(rng.normal(size=x.shape).astype(dtype)
                for x in (state.color, state.trans, state.depth))
    got, want = _kernel_and_walk_rows(p, bins, cam, state, stop_at, saved, cot, config)
    return np.asarray(got), np.asarray(want)
