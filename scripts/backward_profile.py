"""Time the Pallas backward kernel's variants (lgs_jax.backends.pallas.BACKWARD) on real scenes,
forward + backward of sum(image · W) through `render(backend="pallas")`, alternating variants
within each round; then check vmapped vs single-view gradients bit for bit per backend.

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/backward_profile.py [DATA]
"""

import itertools
import statistics
import sys
import time

import jax
import jax.numpy as jnp

import lgs_jax
from lgs_jax.backends import pallas
from lgs_jax.bench import parse_scene

data = sys.argv[1] if len(sys.argv) > 1 else "carry/data"
specs = [f"guitar={data}/guitar/guitar.ply:{data}/guitar/orbit_cameras.json@1280x720",
         f"lego={data}/lego_sh3/lego_sh3.ply:{data}/lego_sh3/lego_cameras.json@800x800"]
print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}")
for spec in specs:
    case = parse_scene(spec)
    g, cam = jax.device_put(case.scene), jax.device_put(case.camera)
    cap = int(lgs_jax.render(g, cam).stats.capacity)
    weights = jax.random.normal(jax.random.key(0), (cam.height, cam.width, 3), jnp.float32)
    fns = {}
    for prefetch, skip in itertools.product([True, False], [True, False]):
        pallas.BACKWARD.update(prefetch=prefetch, skip_empty=skip)
        f = jax.jit(jax.value_and_grad(lambda g: jnp.sum(
            lgs_jax.render(g, cam, backend="pallas", capacity=cap).image * weights)))
        f.lower(g).compile()  # traced now, with this variant
        jax.block_until_ready(f(g))
        fns[f"prefetch={prefetch} skip_empty={skip}"] = f
    times = {k: [] for k in fns}
    for _ in range(20):
        for k, f in fns.items():
            t0 = time.perf_counter()
            jax.block_until_ready(f(g))
            times[k].append(1e3 * (time.perf_counter() - t0))
    for k, t in times.items():
        print(f"{case.name:>8s} {k:<32s} fwd+bwd {statistics.median(t):8.3f} ms")
pallas.BACKWARD.update(prefetch=True, skip_empty=True)

# vmap vs single views, bit for bit (forward image and gradients), per backend.
case = parse_scene(specs[1])
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
