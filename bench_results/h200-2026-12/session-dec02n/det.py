"""Repeatability probe: per row, the jitted value_and_grad called 3 times; per leaf, elements
that differ between calls and the largest difference."""
import sys
sys.path.insert(0, ".")
sys.path.insert(0, "carry")
import jax, jax.numpy as jnp, numpy as np
import ab  # patches binning / walked_rows, rows localgs#...
import lgs_jax
from benchmarks import scale
from benchmarks.common import load_scene
scene, rows = sys.argv[1], sys.argv[2].split(",")
g, cam = load_scene(scene, "carry/data")
g, cam = jax.device_put(g), jax.device_put(cam)
n_pairs = scale.count_pairs(g, cam)
w = jax.random.normal(jax.random.key(0), (cam.height, cam.width, 3), jnp.float32)
for name in rows:
    backend, config, cap = scale.row_setup(name, n_pairs)
    def loss(g, w, b=backend, cf=config, cap=cap):
        out = lgs_jax.render(g, cam, backend=b, config=cf, capacity=cap)
        return jnp.sum(out.image * w)
    f = jax.jit(jax.value_and_grad(loss))
    res = [jax.tree.map(np.asarray, f(g, w)) for _ in range(3)]
    names = ["loss"] + [f"d{k}" for k in ("means", "quats", "log_scales", "logit_opacities", "sh")]
    for i, j in ((0, 1), (1, 2), (0, 2)):
        diffs = []
        for nm, a, b in zip(names, jax.tree.leaves(res[i]), jax.tree.leaves(res[j])):
            d = a != b
            if d.any():
                diffs.append(f"{nm}: {int(d.sum())} differ, max {float(np.abs(a - b).max()):.3g}"
                             f" of {float(np.abs(a).max()):.3g}")
        print(f"{scene} {name} calls {i}-{j}: " + ("same bits" if not diffs else "; ".join(diffs)),
              flush=True)
