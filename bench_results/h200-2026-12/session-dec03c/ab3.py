"""In-process A/B (carried diagnostic, not committed): localgs#new (working tree: sums written
into the table's buffer, the projection barrier's identity derivative) and localgs#old (HEAD's
gaussian_grads.sums as ten columns, the barrier differentiated as itself)."""
import dataclasses, importlib.util, sys
sys.path.insert(0, ".")
from jax import lax
from lgs_jax import projection
from lgs_jax.backends import gaussian_grads as gg
from benchmarks import scale

spec = importlib.util.spec_from_file_location("lgs_jax.backends._gg_old", "carry/gg_old.py")
old = importlib.util.module_from_spec(spec); sys.modules[spec.name] = old
spec.loader.exec_module(old)
mode = {"m": "new"}
new_sums, new_stored = gg.sums, projection._stored
gg.sums = lambda *a: (old.sums if mode["m"] == "old" else new_sums)(*a)
projection._stored = lambda p: (lax.optimization_barrier(p) if mode["m"] == "old"
                                else new_stored(p))
backend, cfg = scale.ROWS["localgs"]
for i, m in enumerate(("new", "old")):
    t = dataclasses.replace(cfg.tuning, tiles_chunk=16 + i)
    scale.ROWS[f"localgs#{m}"] = (backend, dataclasses.replace(cfg, tuning=t))
setup = scale.row_setup
def row_setup(name, n):
    mode["m"] = name.split("#")[1].split("@")[0] if "#" in name else "new"
    return setup(name, n)
scale.row_setup = row_setup
if __name__ == "__main__":
    sys.exit(scale.main(sys.argv[1:]))
