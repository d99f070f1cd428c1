"""Bit-identity of every backend against an older commit: images, alpha, depth and gradients.

    git worktree add /tmp/lgs_old cde8546
    python scripts/bit_identity.py --old /tmp/lgs_old [--seeds 2]

Runs the same matrix twice, in two fresh processes, once with the package of this checkout and
once with the package of `--old` (through PYTHONPATH; only the public API is used, so any commit
since `render(..., backend=, config=, capacity=)` works), and compares every array bit for bit.
Matrix: every backend x config (exact/fast, each Local-GS switch, both conventions, kernel
triton/mosaic for the Pallas backends) x dtype (float32, float64) on small adversarial scenes
(tests/scenes.py: needles, huge far Gaussians, opacity near 1/255, opaque, stacked layers,
invalid rows) at 40x24. Without a GPU the Pallas kernels run in interpret mode (Mosaic GPU's is
slow: a few minutes in all). Gradients: jax.grad of Σ(image·w_i + alpha·w_a + depth·w_d) for
fixed random w, with respect to every Gaussian field and the background.

One change is known and allowed (`ROUNDING`): since the backends' restructuring (issue 14) the
XLA backward walk of `reference` and `tiles` takes the same recurrence step as the Pallas
backward kernels (lgs_jax.backends.backward.walk_step), whose channel dots ḡ_C·rgb and ḡ_C·S_C
are explicit multiply-adds; the walk used to sum them with an XLA reduction over the channel
axis, which rounds differently. Those backends' position, shape and opacity gradients (which go
through ∂L/∂α) may therefore differ from the old commit's by float rounding: the script checks
they stay within ROUNDING_TOLERANCE of each field's largest magnitude and reports them apart.
Everything else (every image, alpha and depth, every Pallas gradient, the colour and background
gradients) must be bit-identical. Exit status 1 otherwise.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROUNDING = ("reference", "tiles")  # row prefixes whose ∂L/∂α-dependent gradients may round
ROUNDING_FIELDS = ("d_means", "d_quats", "d_log_scales", "d_logit_opacities")
ROUNDING_TOLERANCE = {"float32": 1e-4, "float64": 1e-13}  # of the field's max |value|


def matrix():
    """(name, backend, config kwargs) rows."""
    switches = {"exact": {}, "fast": dict(blend="fast"), "no_hoist": dict(hoist=False),
                "no_cull": dict(warp_cull=False), "baseline": dict(hoist=False, warp_cull=False),
                "global": dict(local_coords=False), "center": dict(origin="center")}
    rows = [("brute", "brute", {}), ("brute:gsplat", "brute", dict(convention="gsplat")),
            ("reference", "reference", {}),
            ("reference:gsplat", "reference", dict(convention="gsplat"))]
    for conv in ("3dgs", "gsplat"):
        for name, kw in switches.items():
            if conv == "gsplat" and name not in ("exact", "fast"):
                continue
            rows.append((f"tiles:{conv}:{name}", "tiles", dict(kw, convention=conv)))
            for kernel in ("triton", "mosaic"):
                rows.append((f"pallas:{kernel}:{conv}:{name}", "pallas",
                             dict(kw, convention=conv, kernel=kernel)))
        for blend in ("exact", "fast"):
            for kernel in ("triton", "mosaic"):
                rows.append((f"pallas_vanilla:{kernel}:{conv}:{blend}", "pallas_vanilla",
                             dict(convention=conv, blend=blend, kernel=kernel)))
    return rows


def dump(path: str, seeds: int, only: str | None):
    """Render and differentiate the matrix with whichever `lgs_jax` is importable; save npz."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    import lgs_jax

    sys.path.insert(0, ROOT)
    from tests import scenes

    out = {}
    for seed in range(seeds):
        for dtype in (np.float32, np.float64):
            g = scenes.cast(scenes.scene(1000 + seed), dtype)
            cam = scenes.camera(dtype=dtype)
            bg = np.asarray(scenes.BACKGROUND, dtype)
            rng = np.random.default_rng(seed)
            w = [jnp.asarray(rng.normal(size=s).astype(dtype))
                 for s in ((cam.height, cam.width, 3), (cam.height, cam.width),
                           (cam.height, cam.width))]
            for name, backend, kw in matrix():
                if only and only not in name:
                    continue
                config = lgs_jax.RasterConfig(**kw)

                def outputs(g, bg, backend=backend, config=config):
                    o = lgs_jax.render(g, cam, background=bg, backend=backend, config=config,
                                       capacity=4096)
                    return o.image, o.alpha, o.depth

                def loss(g, bg):
                    image, alpha, depth = outputs(g, bg)
                    return (jnp.sum(image * w[0]) + jnp.sum(alpha * w[1])
                            + jnp.sum(depth * w[2]))

                key = f"{seed}:{np.dtype(dtype).name}:{name}"
                image, alpha, depth = jax.jit(outputs)(g, bg)
                grads = jax.jit(jax.grad(loss, argnums=(0, 1)))(g, bg)
                out[f"{key}:image"], out[f"{key}:alpha"] = np.asarray(image), np.asarray(alpha)
                out[f"{key}:depth"] = np.asarray(depth)
                for field in ("means", "quats", "log_scales", "logit_opacities", "sh"):
                    out[f"{key}:d_{field}"] = np.asarray(getattr(grads[0], field))
                out[f"{key}:d_background"] = np.asarray(grads[1])
                print(key, flush=True)
    np.savez(path, **out)


def _run(tree: str, path: str, seeds: int, only: str | None):
    env = dict(os.environ, PYTHONPATH=tree, JAX_PLATFORMS=os.environ.get("JAX_PLATFORMS", ""))
    cmd = [sys.executable, os.path.abspath(__file__), "--dump", path, "--seeds", str(seeds)]
    if only:
        cmd += ["--only", only]
    subprocess.run(cmd, env=env, check=True, cwd=tempfile.gettempdir(),
                   stdout=subprocess.DEVNULL)


def _rounding_allowed(key: str) -> bool:
    _, _, name = key.split(":", 2)
    return name.split(":")[0] in ROUNDING and key.rsplit(":", 1)[1] in ROUNDING_FIELDS


def compare(old: str, new: str) -> int:
    a, b = np.load(old), np.load(new)
    missing = sorted(set(a.files) ^ set(b.files))
    common = sorted(set(a.files) & set(b.files))
    bad, rounding = [], []
    for k in common:
        x, y = a[k], b[k]
        if x.dtype == y.dtype and x.shape == y.shape and np.array_equal(
                x.view(np.uint8), y.view(np.uint8)):
            continue
        d = np.abs(x.astype(np.float64) - y.astype(np.float64))
        rel = float(np.nanmax(d)) / max(float(np.nanmax(np.abs(x))), 1e-30) if d.size else 0.0
        line = f"{k}: max |diff| {np.nanmax(d):.3g} ({rel:.2g} of max |value|), " \
               f"{int(np.sum(d != 0))} of {d.size} values"
        tol = ROUNDING_TOLERANCE[k.split(":")[1]]
        if _rounding_allowed(k) and x.shape == y.shape and rel <= tol:
            rounding.append(line)
        else:
            bad.append(line)
    for line in rounding:
        print(f"rounding (allowed) {line}")
    for line in bad:
        print(f"DIFFERS {line}")
    for k in missing:
        print(f"MISSING {k}")
    print(f"{len(common) - len(bad) - len(rounding)} of {len(common)} arrays bit-identical; "
          f"{len(rounding)} within the allowed rounding; {len(bad)} differ; {len(missing)} missing")
    return 1 if bad or missing else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old", help="checkout (worktree) of the older commit")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--only", help="only matrix rows whose name contains this")
    ap.add_argument("--keep", help="folder to keep old.npz and new.npz in")
    ap.add_argument("--dump", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.dump:
        dump(args.dump, args.seeds, args.only)
        return 0
    if not args.old:
        ap.error("--old: required")
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or tmp
        os.makedirs(folder, exist_ok=True)
        paths = [os.path.join(folder, f"{k}.npz") for k in ("old", "new")]
        for tree, path in zip((os.path.abspath(args.old), ROOT), paths):
            _run(tree, path, args.seeds, args.only)
        return compare(*paths)


if __name__ == "__main__":
    sys.exit(main())
