"""Probe of the compacted Local-GS forward (`KernelConfig.mosaic_compact`) on the GPU.

1. `mosaic_staging._partition` alone, in a one-block kernel: per round a chunk of 128 table
   rows gathered as the compaction gathers them, kept where column 0 is below the round's
   threshold (none, all, random shares), partitioned into shared memory and copied out; the
   copies are checked against numpy's stable partition (records, pair indices, count).
2. The dense one-tile scene of tests/backends/test_mosaic_staging.py rendered with and without
   the compaction (half-tile blocks): pixels that differ per block, and whether repeated
   compacted renders give the same bits.

    python scripts/probe_compact.py [--interpret]
"""

from __future__ import annotations

import argparse
import functools
import sys

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental.pallas import mosaic_gpu as plgpu

sys.path.insert(0, ".")
import lgs_jax  # noqa: E402
from lgs_jax import pairs  # noqa: E402
from lgs_jax.backends import mosaic_staging as ms  # noqa: E402

LANES = ms.LANES
THRESHOLDS = (0.5, -1.0, 2.0, 0.05, 0.95, 0.5)
COLS = pairs.TABLE_COLUMNS


def partition_kernel(gauss_ref, table_ref, out_rec, out_idx, out_n, *scratch,
                     interpret: bool, last_pair: int):
    buf = scratch[0]
    for r, t in enumerate(THRESHOLDS):
        base = jnp.int32(r * LANES)
        cols = ms.gather(gauss_ref, table_ref, base, last_pair, interpret)
        keep = (cols[0] < t).astype(jnp.int32)
        ms._partition(cols[:ms.ks.REC], keep, base, buf, scratch[1], scratch[2], interpret)
        for c in range(ms.ks.REC):
            out_rec[r, c, :] = buf[c, :]
        idx = scratch[1][...]
        out_idx[r, :] = idx
        out_n[r, :] = idx * 0 + scratch[2][ms.COUNT]


def probe_partition(interpret: bool, dt) -> bool:
    rounds, n = len(THRESHOLDS), len(THRESHOLDS) * LANES
    rng = np.random.default_rng(0)
    gauss = rng.permutation(n).astype(np.int32)
    table = rng.uniform(size=(n, COLS)).astype(dt)
    table[:, 1] = np.arange(n)
    kernel = functools.partial(partition_kernel, interpret=interpret, last_pair=n - 1)
    out = plgpu.kernel(
        kernel, out_type=[jax.ShapeDtypeStruct((rounds, ms.ks.REC, LANES), dt),
                          jax.ShapeDtypeStruct((rounds, LANES), jnp.int32),
                          jax.ShapeDtypeStruct((rounds, LANES), jnp.int32)],
        scratch_types=ms.compact_scratch(dt), grid=(1,), grid_names=("x",),
        interpret=plgpu.InterpretGPUParams() if interpret else None)(
            jnp.asarray(gauss), jnp.asarray(table))
    rec, idx, cnt = (np.asarray(o) for o in out)
    ok = True
    for r, t in enumerate(THRESHOLDS):
        ids = np.arange(r * LANES, (r + 1) * LANES)
        rows = table[gauss[ids]][:, :ms.ks.REC]
        keep = rows[:, 0] < t
        order = np.argsort(~keep, kind="stable")
        good = (np.array_equal(rec[r], rows[order].T) and np.array_equal(idx[r], ids[order])
                and np.all(cnt[r] == keep.sum()))
        ok &= good
        print(f"partition round {r} threshold {t}: kept {keep.sum()} count {cnt[r][0]} "
              f"records {'ok' if np.array_equal(rec[r], rows[order].T) else 'WRONG'} "
              f"indices {'ok' if np.array_equal(idx[r], ids[order]) else 'WRONG'}")
        if not good:
            print("  want idx", ids[order][:40].tolist())
            print("  got  idx", idx[r][:40].tolist())
            bad = np.nonzero(np.any(rec[r] != rows[order].T, axis=0))[0]
            print("  positions with wrong records", bad[:40].tolist())
    return ok


def _config(compact: bool, unroll: int = 8, fwd: int = 128, bwd: int = 128, segment=None):
    return lgs_jax.RasterConfig(kernel="mosaic", tuning=lgs_jax.KernelConfig(
        mosaic_compact=compact, mosaic_forward_pixels=fwd, mosaic_backward_pixels=bwd,
        mosaic_unroll_localgs=unroll, mosaic_backward_segment=segment))


def probe_render(seeds, repeats: int) -> None:
    from tests import scenes
    from tests.backends import test_mosaic_staging as t
    for seed in seeds:
        g64, cam64 = t._dense_tile(seed)
        for dt in (np.float64, np.float32):
            g, cam = scenes.cast(g64, dt), scenes.camera(dtype=dt, **t.TILE_CAMERA)
            ref = np.asarray(lgs_jax.render(g, cam, backend="tiles", capacity=t.CAPACITY).image)
            imgs = {}
            for compact, unroll in ((False, 8), (True, 8), (False, 1), (True, 1)):
                runs = [lgs_jax.render(g, cam, backend="pallas", capacity=t.CAPACITY,
                                       config=_config(compact, unroll))
                        for _ in range(repeats)]
                im = [np.asarray(r.image) for r in runs]
                imgs[compact, unroll] = im[0]
                print(f"seed {seed} {np.dtype(dt).name} compact={compact} unroll={unroll}: "
                      f"repeatable {all(np.array_equal(im[0], i) for i in im[1:])}, max |image"
                      f" - tiles| {np.abs(im[0] - ref).max():.3g}, walked "
                      f"{int(runs[0].stats.pairs_walked)}, kernel {runs[0].stats.kernel}",
                      flush=True)
            for unroll in (8, 1):
                a, b = imgs[True, unroll], imgs[False, unroll]
                differs = np.any(a != b, axis=-1)  # rows 0-7: block 0, rows 8-15: block 1
                print(f"  unroll {unroll}: pixels differing block 0 {differs[:8].sum()}, block 1 "
                      f"{differs[8:].sum()}, max {np.abs(a - b).max():.3g}")
            print("  non-compact unroll 8 vs 1 max", np.abs(imgs[False, 8] - imgs[False, 1]).max())
        g = scenes.cast(g64, np.float32)
        cam = scenes.camera(dtype=np.float32, **t.TILE_CAMERA)
        w = np.random.default_rng(seed).normal(size=(16, 16, 3)).astype(np.float32)
        for compact, fwd, bwd in ((False, 128, 128), (True, 128, 128), (False, 128, 256),
                                  (True, 128, 256), (False, 256, 256)):
            config = _config(compact, fwd=fwd, bwd=bwd, segment=128)
            loss = jax.jit(jax.grad(lambda g, config=config: jnp.sum(lgs_jax.render(
                g, cam, backend="pallas", config=config, capacity=t.CAPACITY).image * w)))
            grads = [np.concatenate([np.ravel(x) for x in jax.tree.leaves(loss(g))])
                     for _ in range(repeats)]
            print(f"  grad f32 compact={compact} fwd {fwd} bwd {bwd}: repeatable "
                  f"{all(np.array_equal(grads[0], x) for x in grads[1:])}, finite "
                  f"{np.isfinite(grads[0]).all()}, |g| {np.abs(grads[0]).max():.4g}", flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--interpret", action="store_true")
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--render", action="store_true", help="the renders in interpret mode too")
    args = ap.parse_args()
    jax.config.update("jax_enable_x64", True)  # as the tests: float64 scenes stay float64
    for dt in (np.float32, np.float64):
        print(f"partition {np.dtype(dt).name}:",
              "OK" if probe_partition(args.interpret, dt) else "FAILED", flush=True)
    if not args.interpret or args.render:
        probe_render([int(s) for s in args.seeds.split(",")], args.repeats)
