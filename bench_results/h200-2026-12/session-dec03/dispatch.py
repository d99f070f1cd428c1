"""Host dispatch probe (carried diagnostic): per call of the jitted forward at a scene, the
blocked end-to-end time, the time until the call returns (dispatch, unblocked), and the time
per call of 10 calls issued back to back then blocked once (pipelined)."""
import sys, time
sys.path.insert(0, ".")
import jax, numpy as np
import lgs_jax
from benchmarks import scale
from benchmarks.common import load_scene
scene = sys.argv[1]
g, cam = load_scene(scene, "carry/data")
g, cam = jax.device_put(g), jax.device_put(cam)
n_pairs = scale.count_pairs(g, cam)
backend, config, cap = scale.row_setup("localgs", n_pairs)
f = jax.jit(lambda g, c: lgs_jax.render(g, c, backend=backend, config=config, capacity=cap).image)
jax.block_until_ready(f(g, cam))
res = {"blocked": [], "dispatch": [], "pipelined": []}
for _ in range(15):
    t0 = time.perf_counter(); out = f(g, cam); t1 = time.perf_counter()
    jax.block_until_ready(out); t2 = time.perf_counter()
    res["dispatch"].append(t1 - t0); res["blocked"].append(t2 - t0)
    t0 = time.perf_counter()
    outs = [f(g, cam) for _ in range(10)]
    jax.block_until_ready(outs); res["pipelined"].append((time.perf_counter() - t0) / 10)
print(scene, "  ".join(f"{k} {1e3 * np.median(v):.3f} ms" for k, v in res.items()), flush=True)
