"""Runs the Pallas rasterization of guitar 1280x720 a few times (for `ncu -k regex:kernel`)."""
import sys
import jax
sys.path.insert(0, ".")
import lgs_jax

g = jax.device_put(lgs_jax.load_ply("carry/data/guitar/guitar.ply"))
cam = lgs_jax.load_cameras("carry/data/guitar/orbit_cameras.json", width=1280, height=720)[0]
for backend in ("pallas", "pallas_vanilla"):
    f = jax.jit(lambda g, c: lgs_jax.render(g, c, backend=backend, capacity=2**19).image)
    for _ in range(3):
        jax.block_until_ready(f(g, cam))
