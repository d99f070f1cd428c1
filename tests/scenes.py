"""Random and adversarial test scenes with fixed shapes (values vary, shapes never do, so a
hypothesis run compiles each function once)."""

from __future__ import annotations

import numpy as np

import lgs_jax

N = 32  # Gaussians per test scene (fixed: no recompiles)
W, H = 40, 24  # image size: not a multiple of 16, so edge tiles are partial

KINDS = ("normal", "needle", "huge_far", "tiny", "behind", "faint", "opaque", "layers", "invalid")


def camera(width=W, height=H, dtype=np.float32, yaw=0.0):
    """Camera at the origin looking down +z (OpenCV axes), optionally yawed."""
    c, s = np.cos(yaw), np.sin(yaw)
    view = np.eye(4)
    view[:3, :3] = [[c, 0, -s], [0, 1, 0], [s, 0, c]]
    f = 0.9 * width
    return lgs_jax.Camera(viewmat=view.astype(dtype), fx=dtype(f), fy=dtype(f),
                          cx=dtype(width / 2), cy=dtype(height / 2), width=width, height=height)


def random_quats(rng, n):
    return rng.normal(size=(n, 4)) * rng.uniform(0.1, 3.0, size=(n, 1))  # not unit length


def scene(seed: int, kinds=KINDS, n=N, sh_bases=4, dtype=np.float64) -> lgs_jax.Gaussians:
    """A scene whose Gaussians are drawn from the listed adversarial kinds.

    normal: in view, moderate size. needle: one long axis, two ~1e-3 axes. huge_far: scales up to
    e^2 and centres far outside the image. tiny: sub-pixel. behind: z < near. faint: opacity within
    ±2% of 1/255. opaque: logit +inf. layers: many Gaussians stacked at one spot, depths ties
    included. invalid: NaN / inf / zero-quaternion rows.
    """
    rng = np.random.default_rng(seed)
    kind = rng.choice(kinds, size=n)
    z = rng.uniform(1.5, 6.0, n)
    means = np.stack([rng.uniform(-0.35, 0.35, n) * z * W / (0.9 * W),
                      rng.uniform(-0.35, 0.35, n) * z * H / (0.9 * W), z], -1)
    log_scales = rng.uniform(-3.5, -1.0, (n, 3))
    logit = rng.normal(0, 2, n)
    quats = random_quats(rng, n)
    sh = rng.normal(0, 0.5, (n, sh_bases, 3))
    for i, k in enumerate(kind):
        if k == "needle":
            log_scales[i] = [rng.uniform(-0.5, 1.0), -7.0, -7.0]
        elif k == "huge_far":
            log_scales[i] = rng.uniform(0.0, 2.0, 3)
            means[i, 0] += rng.choice([-1, 1]) * rng.uniform(5, 40)
        elif k == "tiny":
            log_scales[i] = rng.uniform(-9, -6, 3)
        elif k == "behind":
            means[i, 2] = rng.uniform(-2.0, 0.01)
        elif k == "faint":
            o = (1 / 255) * (1 + rng.uniform(-0.02, 0.02))
            logit[i] = np.log(o / (1 - o))
        elif k == "opaque":
            logit[i] = np.inf
        elif k == "layers":
            means[i] = [0.05, -0.03, 2.0 + 0.25 * rng.integers(0, 3)]
            logit[i] = rng.uniform(0, 4)
        elif k == "invalid":
            which = rng.integers(0, 4)
            if which == 0:
                means[i, rng.integers(0, 3)] = np.nan
            elif which == 1:
                quats[i] = 0.0
            elif which == 2:
                log_scales[i, 0] = np.inf
            else:
                means[i, 0] = -np.inf
    return lgs_jax.Gaussians(means=means.astype(dtype), quats=quats.astype(dtype),
                             log_scales=log_scales.astype(dtype),
                             logit_opacities=logit.astype(dtype), sh=sh.astype(dtype))


def cast(g: lgs_jax.Gaussians, dtype) -> lgs_jax.Gaussians:
    import jax

    return jax.tree.map(lambda x: np.asarray(x, dtype), g)
