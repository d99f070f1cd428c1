"""lgs_jax.pairs: the per-pair strip masks (Local-GS Sec. III-C, Eq. 20–21) are conservative
(every strip with a pixel whose evaluated float alpha test passes has its bit set) for every
evaluated form, on adversarial conics placed on the 1/255 ellipse edge and on projected scenes,
and tight on a real scene."""

import dataclasses
import functools
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st
from jax.extend.core import Literal

import lgs_jax
from lgs_jax import binning, layout, pairs
from lgs_jax.backends import tiles
from lgs_jax.layout import STRIPS
from lgs_jax.projection import project
from tests import scenes

C = lgs_jax.RasterConfig

SLOW = pytest.mark.slow
W, H = 64, 48
M = 16
CAPACITY = 256  # >= M Gaussians x the 4x3 tiles of a W x H image


@functools.partial(jax.jit, static_argnames=("config", "capacity"))
def _masks_and_hits(p, config, capacity):
    """(pairs required, strip mask of every pair slot, whether each of its 8 strips holds a
    pixel whose evaluated float alpha test passes), jitted with the projected Gaussians as
    arguments: one compile per (config, capacity, dtype), whatever the values."""
    tiles_x, _ = layout.tile_grid(W, H)
    bins = binning.bin_gaussians(p, W, H, capacity)
    pg = pairs.gather(p, bins.gauss)
    masks = pairs.strip_masks(pg, bins, tiles_x, config)
    vecs = pairs.hoisted_vectors(pg, bins, tiles_x, config) if config.hoist else None

    def strip_hits(k):
        sid = bins.tile[k] * STRIPS + jnp.arange(STRIPS, dtype=jnp.int32)
        lx, ly, px, py = layout.strip_pixels(sid, tiles_x, p.mean2d.dtype)
        basis = tiles.pixel_basis(lx, ly, px, py, config)
        g = jnp.full((STRIPS, 1), bins.gauss[k])
        v = None if vecs is None else jnp.broadcast_to(vecs[k], (STRIPS, 1, 7))
        inside = (px < W) & (py < H)  # edge tiles: pixels past the image are never shown
        _, hit = tiles.evaluate(p, g, v, basis, px, py, config)
        return jnp.any(hit[0] & inside, axis=-1)  # (8,)

    return bins.pairs_required, masks, jax.vmap(strip_hits)(jnp.arange(capacity))


def _check_masks(p, config, capacity=CAPACITY):
    """Every tile pixel where the evaluated float alpha test passes lies in a set strip.

    Evaluates all `capacity` pair slots (a fixed shape: no recompiles), then keeps the real ones.
    """
    n, masks, hits = _masks_and_hits(p, config, capacity)
    n = int(n)
    assert n <= capacity
    masks, hits = np.asarray(masks)[:n], np.asarray(hits)[:n]
    bits = (masks[:, None] >> np.arange(STRIPS)) & 1
    missed = hits & (bits == 0)
    assert not missed.any(), f"{missed.sum()} strips with passing pixels have a clear mask bit"
    return hits.sum(), bits.sum()


MASK_CONFIGS = {"difference": C(hoist=False), "local_corner": C(),
                "local_center": C(origin="center"), "global": C(local_coords=False)}


@pytest.mark.parametrize("name,dtype", [(name, np.float32) for name in MASK_CONFIGS]
                         + [pytest.param(name, np.float64, marks=SLOW) for name in MASK_CONFIGS])
@given(log_kappa=scenes.float_arrays(0, np.log(1e7), M),
       theta=scenes.float_arrays(0, np.pi, M), log_lmin=scenes.float_arrays(-8, 7, M),
       angle=scenes.float_arrays(0, 2 * np.pi, M),
       logit=scenes.float_arrays(np.log(1 / 254), 12, M),
       edge=scenes.float_arrays(-3e-6, 3e-6, M),
       pixel=st.lists(st.tuples(st.integers(0, W - 1), st.integers(0, H - 1)), min_size=M,
                      max_size=M))
def test_strip_masks_are_conservative(name, dtype, log_kappa, theta, log_lmin, angle, logit,
                                      edge, pixel):
    p = scenes.projected_conics(dtype, log_kappa, theta, log_lmin, np.zeros(M), angle, logit,
                                edge=edge, edge_pixel=np.asarray(pixel))
    _check_masks(p, MASK_CONFIGS[name])


@given(seed=st.integers(0, 2**32 - 1))
def test_strip_masks_on_projected_scenes_float32(seed):
    g = scenes.cast(scenes.scene(seed, n=M), np.float32)
    _check_masks(project(g, scenes.camera(W, H)), C())


def test_strip_masks_are_tight_on_a_real_scene(data_dir, capsys):
    """How much work the masks keep: needed strips (with a passing pixel) vs set strips."""
    g = lgs_jax.load_ply(os.path.join(data_dir, "lego_sh3", "lego_sh3.ply"))
    cam = lgs_jax.load_cameras(os.path.join(data_dir, "lego_sh3", "lego_cameras.json"),
                               width=W, height=H)[0]
    needed, kept = _check_masks(project(g, cam), C(), capacity=2**17)
    with capsys.disabled():
        print(f"\nlego 64x48 strip masks: {needed} strips needed, {kept} set "
              f"(tightness {needed / max(kept, 1):.3f})")
    assert needed / kept > 0.8


@pytest.mark.parametrize("seed", [0, 1])
def test_padded_ellipse_det_lo_is_positive_on_adversarial_scenes(seed):
    """What the strip masks' division by det_lo relies on (`pairs.strip_mask_columns`): det_lo
    > 0 for every Gaussian (NaN only where the projection is NaN: invalid rows, which no pair
    reaches), and exactly 1 where the ellipse cannot be bounded."""
    g = scenes.scene(seed, kinds=scenes.KINDS, n=400)
    p = project(g, scenes.camera(width=W, height=H))
    # and singular or nearly singular conics (a·c = b², or 1 ulp off), which it cannot bound
    conic = np.asarray(p.conic).copy()
    conic[:40] = [1.0, 1.0, 1.0]
    conic[40:80, 2] = np.nextafter(conic[40:80, 0] ** -1, np.inf) * conic[40:80, 1] ** 2
    p = dataclasses.replace(p, conic=jnp.asarray(conic))
    e = binning.padded_ellipse(p)
    det_lo, unbounded = np.asarray(e.det_lo), np.asarray(e.unbounded)
    assert unbounded.any()
    assert not np.any(det_lo <= 0)
    assert np.all(det_lo[unbounded] == 1)
    assert np.all(np.isfinite(det_lo[np.asarray(p.valid)]))
    # The strip masks' ellipse, computed from the table's columns (`strip_mask_columns`), is
    # binning's for every valid Gaussian, bit for bit.
    valid, rows = np.asarray(p.valid), pairs.gaussian_table(p)
    m = binning.ellipse_bound(rows[:, 2], rows[:, 3], rows[:, 4], rows[:, 5])
    for field in ("tau", "tau_pad", "det_lo", "unbounded"):
        np.testing.assert_array_equal(np.asarray(getattr(m, field))[valid],
                                      np.asarray(getattr(e, field))[valid], err_msg=field)


@pytest.mark.parametrize("hoist", [True, False])
def test_record_columns_are_computed_from_the_lanes_data(hoist):
    """Every column of `pairs.record_columns` without a mask is computed from the Gaussians'
    own columns, none a constant: the Mosaic GPU kernels store the columns with lane-strided
    inline stores, which a constant's splat fails to build for (LLVM translation), and on the
    H200 the kernels without warp culling hung their tests."""
    cols = [jnp.arange(8, dtype=jnp.float32) + i for i in range(pairs.TABLE_COLUMNS)]
    config = lgs_jax.RasterConfig(hoist=hoist, warp_cull=False)
    tx, ty = jnp.int32(3), jnp.int32(2)
    jaxpr = jax.make_jaxpr(lambda c: pairs.record_columns(c, tx, ty, config))(cols).jaxpr
    made_by = {v: e for e in jaxpr.eqns for v in e.outvars}

    def from_lanes(v) -> bool:
        if isinstance(v, Literal) or v not in made_by:  # a constant, an input or a captured one
            return not isinstance(v, Literal) and v in jaxpr.invars
        return any(from_lanes(u) for u in made_by[v].invars)

    for c, v in enumerate(jaxpr.outvars):
        assert from_lanes(v), f"record column {c} is a constant"


# Slow: without warp culling (a render compiled for that config alone); the count is then
# 8 per pair, which tests/backends/test_tiles.py::test_strip_pairs_report_culling checks the
# `tiles` backend reports.
@pytest.mark.parametrize("config", [C(), pytest.param(C(warp_cull=False), marks=SLOW)],
                         ids=["warp_cull", "no_warp_cull"])
def test_strip_pair_count_is_what_the_tiles_backend_reports(config):
    """`pairs.strip_pair_count` (the count the Mosaic GPU kernels do not report) equals the
    `tiles` backend's strip pairs, with and without warp culling."""
    from lgs_jax.layout import tile_grid

    g = scenes.cast(scenes.scene(3), np.float32)
    cam = scenes.camera()
    p, bins = scenes.projected_bins(g, cam)
    out = scenes.render(g, cam, "tiles", config)
    count = jax.jit(pairs.strip_pair_count, static_argnums=(2, 3))(
        p, bins, tile_grid(cam.width, cam.height)[0], config)
    assert int(count) == int(out.stats.backend_stats.strip_pairs)
