import time, dataclasses, numpy as np, jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import lgs_jax
from tests import scenes
C, K = lgs_jax.RasterConfig, lgs_jax.KernelConfig
def deep(seed, n, dtype):
    g = scenes.scene(seed, kinds=("normal",), n=n)
    rng = np.random.default_rng(seed)
    means = np.stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-1.2, 1.2, n), rng.uniform(2.0, 4.0, n)], -1)
    log_scales = rng.uniform(-0.3, 0.3, (n, 3))
    logit = rng.uniform(-5.5, -3, n)
    wall = np.arange(n) % 5 == 0
    means[wall, 1] = rng.uniform(-1.7, -0.3, n)[wall]; means[wall, 0] = rng.uniform(-2, 2, n)[wall]
    means[wall, 2] = rng.uniform(2.8, 3.2, n)[wall]
    log_scales[wall] = rng.uniform(-1.0, -0.5, (n, 3))[wall]
    logit[wall] = rng.uniform(0, 3, n)[wall]
    return scenes.cast(dataclasses.replace(g, means=means, log_scales=log_scales, logit_opacities=logit), dtype)
size=16
g = deep(0, 700, np.float64); cam = scenes.camera(size, size, dtype=np.float64)
cfg = C(kernel="mosaic", tuning=K(mosaic_forward_pixels=128, mosaic_backward_pixels=256, mosaic_backward_segment=None))
out = lgs_jax.render(g, cam, backend="pallas", config=cfg, capacity=2048)
print(int(out.stats.pairs_walked))
print(out.__dict__.keys() if hasattr(out,'__dict__') else out._fields)
from lgs_jax import binning
from lgs_jax.projection import project
from lgs_jax.backends import REGISTRY
p = project(g, cam); bins = binning.bin_gaussians(p, size, size, 2048)
r = REGISTRY["pallas"].rasterize(p, bins, size, size, cfg)
print(np.asarray(r.stop).reshape(size, size)[::2, ::3])
print(np.asarray(1-r.trans).reshape(size,size)[::2, ::3].round(3))
s = np.asarray(r.stop).reshape(size, size)
print("top max", s[:8].max(), "top stops in (384,512]:", ((s[:8] > 384) & (s[:8] <= 512)).sum(), "bottom min", s[8:].min())
from lgs_jax.backends import pallas_mosaic
cfgc = C(kernel="mosaic", tuning=K(mosaic_forward_pixels=128, mosaic_backward_pixels=256, mosaic_backward_segment=128))
print("compacts", pallas_mosaic.compacts(cfgc))
w = np.random.default_rng(0).normal(size=(size, size, 3))
def grads(config, rc=None):
    @jax.jit
    def f(g):
        def loss(g):
            out = lgs_jax.render(g, cam, backend="pallas", config=config, capacity=2048, row_capacity=rc)
            return jnp.sum(out.image * w) + jnp.sum(out.alpha * w[..., 0]) + 0.1 * jnp.sum(out.depth * w[..., 1]), out.stats
        return jax.grad(loss, has_aux=True)(g)
    return f(g)
t = time.time(); whole, st_ = grads(cfg); print("whole", time.time() - t, int(st_.pairs_walked))
t = time.time(); split, _ = grads(cfgc); print("split", time.time() - t)
t = time.time(); splitw, _ = grads(cfgc, int(st_.pairs_walked)); print("split walked", time.time() - t)
for a, b, c in zip(jax.tree.leaves(whole), jax.tree.leaves(split), jax.tree.leaves(splitw)):
    a, b, c = map(np.asarray, (a, b, c)); sc = np.max(np.abs(a))
    print(np.max(np.abs(b - a)) / sc, np.max(np.abs(c - a)) / sc, np.isfinite(b).all(), np.isfinite(c).all())
