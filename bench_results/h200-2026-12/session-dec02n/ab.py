"""In-process A/B rows (carried diagnostic, not committed): localgs#both (as committed),
#fill (no counts barrier), #none (no binning barriers), #oldrows (walked_rows scattering the
flags by slot, as before). tiles_chunk, unused by pallas, differs per row so render retraces."""
import dataclasses, sys, types
sys.path.insert(0, ".")
import jax.numpy as jnp
from jax import lax
import lgs_jax.binning as b
from lgs_jax.backends import gaussian_grads as gg
from benchmarks import scale

real = lax.optimization_barrier
mode = {"m": "both"}
def barrier(x):
    if mode["m"] == "none" or (mode["m"] == "fill" and not isinstance(x, tuple)):
        return x
    return real(x)
ns = types.SimpleNamespace(**{k: getattr(lax, k) for k in dir(lax) if not k.startswith("__")})
ns.optimization_barrier = barrier
b.lax = ns
new_rows = gg.walked_rows
def old_rows(bins, stop, row_capacity):
    capacity, n_tiles = bins.gauss.shape[0], bins.tile_start.shape[0]
    last = gg.tile_last(stop, bins.tile_start, bins.tile_end)
    real_ = bins.tile < n_tiles
    walked = real_ & (jnp.arange(capacity, dtype=jnp.int32) < last[jnp.where(real_, bins.tile, 0)])
    by_slot = jnp.zeros((capacity,), jnp.int32).at[bins.slot].set(
        walked.astype(jnp.int32), unique_indices=True)
    before = jnp.concatenate([jnp.zeros((1,), jnp.int32), jnp.cumsum(by_slot)])
    at = jnp.where(walked, jnp.minimum(before[bins.slot], row_capacity), row_capacity)
    row_first = jnp.minimum(before[bins.first], row_capacity)
    row_end = jnp.minimum(before[bins.first + bins.count], row_capacity)
    return gg.RowLayout(at=at, end=last, first=row_first, count=row_end - row_first,
                        size=row_capacity + 1)
gg.walked_rows = lambda *a: (old_rows if mode["m"] == "oldrows" else new_rows)(*a)
backend, cfg = scale.ROWS["localgs"]
for i, m in enumerate(("both", "fill", "none", "oldrows")):
    t = dataclasses.replace(cfg.tuning, tiles_chunk=16 + i)
    scale.ROWS[f"localgs#{m}"] = (backend, dataclasses.replace(cfg, tuning=t))
def set_mode(name):
    mode["m"] = name.split("#")[1].split("@")[0] if "#" in name else "both"
setup = scale.row_setup
def row_setup(name, n):
    mode["m"] = name.split("#")[1].split("@")[0] if "#" in name else "both"
    return setup(name, n)
scale.row_setup = row_setup
if __name__ == "__main__":
    sys.exit(scale.main(sys.argv[1:]))
