"""Vmapped vs single-view loss and gradients, bit for bit, per differentiable backend (two
192x192 crops of a lego_sh3 view), reporting the largest difference.

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/vmap_gpu_probe.py [DATA]
"""

import sys

import jax
import jax.numpy as jnp

import lgs_jax
from lgs_jax.bench import parse_scene

data = sys.argv[1] if len(sys.argv) > 1 else "carry/data"
print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}")
case = parse_scene(f"lego={data}/lego_sh3/lego_sh3.ply:{data}/lego_sh3/lego_cameras.json@800x800")
g = jax.device_put(case.scene)
cams = [case.camera.cropped(300, 300, 192, 192), case.camera.cropped(320, 280, 192, 192)]
stacked = lgs_jax.stack_cameras(cams)
w = jax.random.normal(jax.random.key(1), (192, 192, 3), jnp.float32)
for backend in ("pallas", "pallas_vanilla", "reference"):
    loss = lambda g, c: jnp.sum(lgs_jax.render(g, c, backend=backend,
                                               capacity=1 << 20).image * w)
    step = jax.jit(jax.value_and_grad(loss))
    batched = jax.jit(jax.vmap(step, in_axes=(None, 0)))(g, stacked)
    diffs, rel = [], []
    for i, c in enumerate(cams):
        single = step(g, c)
        for a, b in zip(jax.tree.leaves(batched), jax.tree.leaves(single)):
            diffs.append(float(jnp.max(jnp.abs(a[i] - b))))
            rel.append(diffs[-1] / max(float(jnp.max(jnp.abs(b))), 1e-30))
    print(f"vmap vs single {backend:<15s} max |diff| over loss and gradients: {max(diffs):.3g}"
          f" (relative to each leaf's max: {max(rel):.3g}); bitwise: {max(diffs) == 0}")
