"""In-process A/B of two packages (carried diagnostic, not committed): this tree's lgs_jax
against carry/old/lgs_old (the package at cdc3380, before the split backward's entries, renamed):
forward + backward of Σ image·w (value_and_grad, all fields), default rows and walked rows,
alternating rounds; memory = XLA's compiled temporaries + outputs; bits compared."""
import sys
sys.path[:0] = [".", "carry/old"]
import jax, jax.numpy as jnp, numpy as np
import lgs_jax, lgs_old
from benchmarks import scale
from benchmarks.common import compiled_mib, median_ms, parse_scene

scene, repeat = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 7
forward_only = len(sys.argv) > 3 and sys.argv[3] == "fwd"  # the image alone, default rows
case = parse_scene(scene, "carry/data")  # a SCENES name, or e.g. synthetic:300@32x32
g, cam = case.scene, case.camera
g, cam = jax.device_put(g), jax.device_put(cam)
cap = lgs_jax.pair_capacity(scale.count_pairs(g, cam))
w = jax.random.normal(jax.random.key(0), (cam.height, cam.width, 3), jnp.float32)
walked = int(lgs_jax.render(g, cam, backend="pallas", capacity=cap).stats.pairs_walked)
rows_cap = lgs_jax.pair_capacity(walked)
fns, mem, out = {}, {}, {}
for pkg in (lgs_jax, lgs_old):
    gp = pkg.Gaussians(**{k: getattr(g, k) for k in g.__dataclass_fields__})
    cp = pkg.Camera(**{k: getattr(cam, k) for k in cam.__dataclass_fields__})
    for rc in ((None,) if forward_only else (None, rows_cap)):
        name = f"{pkg.__name__}{'@walked' if rc else ''}"
        def loss(gp, w, pkg=pkg, rc=rc, cp=cp):
            return jnp.sum(pkg.render(gp, cp, backend="pallas", capacity=cap,
                                      row_capacity=rc).image * w)
        f = jax.jit(loss if forward_only else jax.value_and_grad(loss))
        out[name] = [np.asarray(x) for x in jax.tree.leaves(f(gp, w))]
        mem[name] = compiled_mib(f, gp, w)
        fns[name] = lambda f=f, gp=gp: jax.block_until_ready(f(gp, w))
ms = median_ms(fns, repeat)
for name in fns:
    ref = out[name.replace("lgs_jax", "lgs_old")]
    same = all(np.array_equal(a, b) for a, b in zip(out[name], ref))
    print(f"{scene:>18} {name:<16} {'fwd' if forward_only else 'fwd+bwd'} {ms[name]:7.2f} ms  mem {mem[name]:7.0f} MiB"
          f"  same bits as lgs_old: {same}", flush=True)
