"""Whether narrower tile keys make the tile sort cheaper (issue 17): `binning.sort_pairs` sorts
(int32 tile, int32 slot) stably by tile. A 4K image has 32400 tiles, so the keys fit 16 bits; a
radix sort over 16-bit keys needs half the passes of one over 32-bit keys, if XLA's GPU sort
(CUB's radix sort, where XLA rewrites the sort to it) takes them.

    python scripts/probe_sort_keys.py [--sizes 4000000,25000000] [--repeat 20]

Times each key type on the same random tiles (uniform in [0, 32400], the 4K grid), checks that
every variant returns the same permutation as the int32 sort, and prints whether the compiled
sort is a CUB custom call.
"""

from __future__ import annotations

import argparse
import sys

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

sys.path.insert(0, ".")
from benchmarks.common import median_ms  # noqa: E402

N_TILES = 32400


def sort_by(dtype):
    def f(tile):
        slot = jnp.arange(tile.shape[0], dtype=jnp.int32)
        return lax.sort((tile.astype(dtype), slot), num_keys=1, is_stable=True)[1]
    return jax.jit(f)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", default="4000000,25000000")
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args()
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    variants = {"int32": jnp.int32, "int16": jnp.int16, "uint16": jnp.uint16}
    for n in map(int, args.sizes.split(",")):
        tile = jnp.asarray(np.random.default_rng(0).integers(0, N_TILES + 1, n), jnp.int32)
        fns = {k: sort_by(dt) for k, dt in variants.items()}
        want = np.asarray(fns["int32"](tile))
        for k, f in fns.items():
            hlo = f.lower(tile).compile().as_text()
            same = np.array_equal(np.asarray(f(tile)), want)
            print(f"n={n} {k}: cub={'cub' in hlo.lower()} same_permutation={same}", flush=True)
        ms = median_ms({k: (lambda f=f: jax.block_until_ready(f(tile))) for k, f in fns.items()},
                       args.repeat)
        print(f"n={n} " + " ".join(f"{k} {v:.3f} ms" for k, v in ms.items()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
