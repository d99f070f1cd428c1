"""Where do vmapped and single-view renders differ in bits on this device? (diagnostic)"""
import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import lgs_jax  # noqa: E402
from lgs_jax.projection import project  # noqa: E402
from tests import scenes  # noqa: E402

g = scenes.cast(scenes.scene(9), np.float32)
cams = [scenes.camera(yaw=y) for y in (-0.2, 0.25)]
batch = lgs_jax.stack_cameras(cams)
pv = jax.jit(jax.vmap(project, in_axes=(None, 0)))(g, batch)
for i, cam in enumerate(cams):
    p1 = jax.jit(project)(g, cam)
    for f in ("mean2d", "conic", "rgb", "opacity", "depth"):
        d = np.abs(np.asarray(getattr(pv, f)[i]) - np.asarray(getattr(p1, f))).max()
        print(f"view {i} projection {f:8s} max diff {d:.3g}")
for backend in ("reference", "tiles"):
    f = jax.jit(jax.vmap(lambda g, c: lgs_jax.render(g, c, backend=backend, capacity=4096).image,
                         in_axes=(None, 0)))
    one = jax.jit(lambda g, c: lgs_jax.render(g, c, backend=backend, capacity=4096).image)
    out = f(g, batch)
    for i, cam in enumerate(cams):
        a, b = np.asarray(one(g, cam)), np.asarray(one(g, cam))
        print(f"{backend:9s} view {i}: vmap vs single {np.abs(np.asarray(out[i]) - a).max():.3g};"
              f" repeated single identical: {np.array_equal(a, b)}")
