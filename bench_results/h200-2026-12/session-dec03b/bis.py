"""Repeatability bisection: per variant, jitted value_and_grad of Σ image·w called 3 times;
per leaf, elements that differ between calls. lgs_old = HEAD's package (control)."""
import sys, types
sys.path[:0] = [".", "carry", "carry/old"]
import jax, jax.numpy as jnp, numpy as np
import lgs_jax, lgs_old
from lgs_jax.backends import gaussian_grads
from benchmarks import scale
from benchmarks.common import load_scene

scene, variants = sys.argv[1], sys.argv[2].split(",")
g, cam = load_scene(scene, "carry/data")
g, cam = jax.device_put(g), jax.device_put(cam)
n_pairs = scale.count_pairs(g, cam)
cap = lgs_jax.pair_capacity(n_pairs)
w = jax.random.normal(jax.random.key(0), (cam.height, cam.width, 3), jnp.float32)
zeros = jnp.zeros((cam.height, cam.width), jnp.float32)
walked = int(lgs_jax.render(g, cam, backend="pallas", capacity=cap).stats.pairs_walked)
rows = lgs_jax.pair_capacity(walked)
barrier = gaussian_grads.lax
for v in variants:
    pkg = lgs_old if v.startswith("old") else lgs_jax
    gaussian_grads.lax = (types.SimpleNamespace(**{k: getattr(jax.lax, k) for k in dir(jax.lax)
                                                   if not k.startswith("__")},
                                                optimization_barrier=lambda x: x)
                          if "nobarrier" in v else barrier)
    rc = rows if "walked" in v else None
    depth = "depth" in v
    def loss(g, w, z, pkg=pkg, rc=rc, depth=depth):
        if pkg is lgs_old:
            g = lgs_old.Gaussians(**{k: getattr(g, k) for k in g.__dataclass_fields__})
            c = lgs_old.Camera(**{k: getattr(cam, k) for k in cam.__dataclass_fields__})
        else:
            c = cam
        out = pkg.render(g, c, backend="pallas", capacity=cap, row_capacity=rc)
        s = jnp.sum(out.image * w)
        return s + jnp.sum(out.depth * z) if depth else s
    f = jax.jit(jax.value_and_grad(loss))
    res = [jax.tree.map(np.asarray, f(g, w, zeros)) for _ in range(3)]
    names = ["loss"] + [f"d{k}" for k in ("log_scales", "logit_opacities", "means", "quats", "sh")]
    out = []
    for i, j in ((0, 1), (1, 2)):
        diffs = []
        for nm, a, b in zip(names, jax.tree.leaves(res[i]), jax.tree.leaves(res[j])):
            a, b = np.atleast_1d(a), np.atleast_1d(b); d = a.view(np.uint8) != b.view(np.uint8)
            if d.any():
                diffs.append(f"{nm}: {int(d.sum())} bytes differ, max "
                             f"{float(np.nanmax(np.abs(a - b), initial=0)):.3g}, nan {int(np.isnan(a).sum())}/{int(np.isnan(b).sum())}")
        out.append(f"{i}-{j}: " + ("same" if not diffs else "; ".join(diffs)))
    print(f"{scene} {v:18s} " + " | ".join(out), flush=True)
