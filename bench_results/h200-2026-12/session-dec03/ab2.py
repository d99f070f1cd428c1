"""In-process A/B rows (carried diagnostic, not committed): localgs#new (as committed) and
localgs#oldat (walked_rows gathering `before` at every pair's slot, as before). tiles_chunk,
unused by pallas, differs per row so render retraces."""
import dataclasses, sys
sys.path.insert(0, ".")
import jax.numpy as jnp
from lgs_jax.backends import gaussian_grads as gg
from benchmarks import scale

mode = {"m": "new"}
new_rows = gg.walked_rows
def old_rows(bins, stop):
    capacity, n_tiles = bins.gauss.shape[0], bins.tile_start.shape[0]
    last = gg.tile_last(stop, bins.tile_start, bins.tile_end)
    real = bins.tile < n_tiles
    index = jnp.arange(capacity, dtype=jnp.int32)
    walked = real & (index < last[jnp.where(real, bins.tile, 0)])
    last_slot = jnp.where(last > bins.tile_start, bins.slot[jnp.maximum(last - 1, 0)], -1)
    tile_of_slot = bins.emitted_tile.astype(jnp.int32)
    emitted = tile_of_slot < n_tiles
    by_slot = emitted & (index <= last_slot[jnp.where(emitted, tile_of_slot, 0)])
    before = jnp.concatenate([jnp.zeros((1,), jnp.int32), jnp.cumsum(by_slot, dtype=jnp.int32)])
    row = jnp.where(walked, before[bins.slot], -1)
    row_first = before[bins.first]
    return gg.RowNumbers(row=row, end=last, first=row_first,
                         count=before[bins.first + bins.count] - row_first, walked=before[-1])
gg.walked_rows = lambda *a: (old_rows if mode["m"] == "oldat" else new_rows)(*a)
backend, cfg = scale.ROWS["localgs"]
for i, m in enumerate(("new", "oldat")):
    t = dataclasses.replace(cfg.tuning, tiles_chunk=16 + i)
    scale.ROWS[f"localgs#{m}"] = (backend, dataclasses.replace(cfg, tuning=t))
setup = scale.row_setup
def row_setup(name, n):
    mode["m"] = name.split("#")[1].split("@")[0] if "#" in name else "new"
    return setup(name, n)
scale.row_setup = row_setup
if __name__ == "__main__":
    sys.exit(scale.main(sys.argv[1:]))
