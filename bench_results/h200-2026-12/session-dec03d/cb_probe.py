"""Probe (carried, not committed): the forward's wall time per call under XLA compiler options
(command buffers on/off), and how long the call takes to return (host dispatch) vs blocked."""
import sys, time, statistics
sys.path[:0] = ["."]
import jax, jax.numpy as jnp
import lgs_jax
from benchmarks import scale
from benchmarks.common import parse_scene

scene, repeat = sys.argv[1], int(sys.argv[2])
case = parse_scene(scene, "carry/data")
g, cam = jax.device_put(case.scene), jax.device_put(case.camera)
cap = lgs_jax.pair_capacity(scale.count_pairs(g, cam))
variants = {"default": None, "no_cb": {"xla_gpu_enable_command_buffer": ""},
            "autotune0": {"xla_gpu_autotune_level": 0}}
fns = {}
for name, opts in variants.items():
    try:
        f = jax.jit(lambda g: lgs_jax.render(g, cam, backend="pallas", capacity=cap).image,
                    compiler_options=opts)
        jax.block_until_ready(f(g))
        fns[name] = f
    except Exception as e:
        print(name, "failed:", type(e).__name__, str(e)[:200])
wall = {n: [] for n in fns}; disp = {n: [] for n in fns}
for _ in range(repeat):
    for n, f in fns.items():
        t0 = time.perf_counter(); out = f(g); t1 = time.perf_counter()
        jax.block_until_ready(out); t2 = time.perf_counter()
        wall[n].append(t2 - t0); disp[n].append(t1 - t0)
for n in fns:
    print(f"{scene:>18} {n:<10} wall {1e3*statistics.median(wall[n]):6.3f} ms  "
          f"returns after {1e3*statistics.median(disp[n]):6.3f} ms", flush=True)
