"""Split backward vs whole walks: gradients of Σ image·w at one scene for (a) whole walks
(mosaic_backward_segment None: no checkpoints), (b) this tree's split backward, (c) HEAD's
(lgs_old) split backward; per leaf, max |x - whole| / max |whole| and NaN counts."""
import dataclasses, sys
sys.path[:0] = [".", "carry", "carry/old"]
import jax, jax.numpy as jnp, numpy as np
import lgs_jax, lgs_old
from benchmarks import scale
from benchmarks.common import load_scene

scene = sys.argv[1]
g, cam = load_scene(scene, "carry/data")
g, cam = jax.device_put(g), jax.device_put(cam)
cap = lgs_jax.pair_capacity(scale.count_pairs(g, cam))
w = jax.random.normal(jax.random.key(0), (cam.height, cam.width, 3), jnp.float32)


def grads(pkg, segment="default"):
    cfg = pkg.RasterConfig()
    if segment != "default":
        cfg = dataclasses.replace(cfg, tuning=dataclasses.replace(cfg.tuning,
                                                                  mosaic_backward_segment=segment))
    def loss(g, w):
        gg, c = g, cam
        if pkg is lgs_old:
            gg = lgs_old.Gaussians(**{k: getattr(g, k) for k in g.__dataclass_fields__})
            c = lgs_old.Camera(**{k: getattr(cam, k) for k in cam.__dataclass_fields__})
        return jnp.sum(pkg.render(gg, c, backend="pallas", config=cfg, capacity=cap).image * w)
    f = jax.jit(jax.grad(loss))
    return [np.asarray(x) for x in jax.tree.leaves(f(g, w))]


names = ["log_scales", "logit_opacities", "means", "quats", "sh"]
whole = grads(lgs_jax, None)
for label, got in (("new split", grads(lgs_jax)), ("HEAD split", grads(lgs_old))):
    parts = []
    for n, a, b in zip(names, got, whole):
        scale_ = np.nanmax(np.abs(b))
        parts.append(f"{n} {np.nanmax(np.abs(a - b)) / scale_:.2e} (NaN {int(np.isnan(a).sum())},"
                     f" >1e-3 rel: {int((np.abs(a - b) > 1e-3 * scale_).sum())})")
    print(f"{scene} {label} vs whole walks: " + "; ".join(parts), flush=True)
