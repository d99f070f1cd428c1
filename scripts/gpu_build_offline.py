"""Do the Mosaic GPU and Triton kernels of every configuration the GPU tests run build for the
H200? Checked on a machine without a GPU, before a device call is spent on it.

    build/gpu-offline/bin/python scripts/gpu_build_offline.py [--only NAME ...] [--n 300]

Each case (`cases`: the kernel variants of tests/backends/test_gradients.py and
tests/backends/pallas/, float32 and float64) compiles the value and
gradient of Σ image·w of a small random scene for the H200 (deviceless, as
`scripts/gpu_memory_offline.py`: `interpret` forced False), with the process's stderr caught
per case: the GPU compiler's errors (e.g. "LLVM Translation failed") are printed there, not
raised, and the kernel is left out of the program. On the GPU such a kernel then fails at run
time, or (a record column that was a constant splat) the test waits forever. Interpret mode
(the CPU tests) and `test_in_kernel_staging_lowers_for_the_gpu`
(lowering to MLIR only) cannot see these errors. Exit status 1 when a case has any.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
sys.path.insert(0, ROOT)

from gpu_memory_offline import CUB_DEVICE, target_device  # noqa: E402


def cases():
    """name -> (backend, RasterConfig, dtype)."""
    import numpy as np

    from lgs_jax import KernelConfig as K
    from lgs_jax import RasterConfig as C

    mosaic = dict(kernel="mosaic")
    out = {
        "local_gs": ("pallas", C(**mosaic)),
        "no_cull": ("pallas", C(warp_cull=False, **mosaic)),
        "difference": ("pallas", C(hoist=False, **mosaic)),
        "global": ("pallas", C(local_coords=False, **mosaic)),
        "center": ("pallas", C(origin="center", **mosaic)),
        "gsplat": ("pallas", C("gsplat", **mosaic)),
        "full_walks": ("pallas", C(tuning=K(backward_segment=64), **mosaic)),
        "fast": ("pallas", C(blend="fast", **mosaic)),
        "vanilla": ("pallas_vanilla", C(**mosaic)),
        "triton": ("pallas", C(kernel="triton")),
    }
    out = {k: (b, c, np.float32) for k, (b, c) in out.items()}
    for name in ("local_gs", "no_cull", "global", "vanilla"):
        out[f"{name}_f64"] = out[name][:2] + (np.float64,)
    return out


def build(backend: str, config, dtype, n: int, sharding) -> tuple[list[str], str]:
    """(error lines the compiler printed, the exception's text if it was not the expected
    missing device) of the gradient of Σ image·w, compiled for the target."""
    import jax
    import jax.numpy as jnp

    import lgs_jax
    from lgs_jax.synthetic import random_scene, synthetic_camera

    config = dataclasses.replace(config, tuning=dataclasses.replace(config.tuning,
                                                                    interpret=False))
    g = jax.tree.map(lambda x: x.astype(dtype) if x.dtype.kind == "f" else x, random_scene(n))
    cam = jax.tree.map(lambda x: x.astype(dtype) if getattr(x, "dtype", None) is not None
                       and x.dtype.kind == "f" else x, synthetic_camera(96, 64))

    def loss(g, w):
        return jnp.sum(lgs_jax.render(g, cam, backend=backend, config=config,
                                      capacity=lgs_jax.pair_capacity(16 * n)).image * w)

    spec = lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding)
    args = (jax.tree.map(spec, g), spec(jnp.zeros((64, 96, 3), dtype)))
    with tempfile.TemporaryFile("w+") as err:
        saved = os.dup(2)
        os.dup2(err.fileno(), 2)
        try:
            jax.jit(jax.value_and_grad(loss)).lower(*args).compile()
            raised = ""
        except Exception as e:  # noqa: BLE001 - without a device XLA fails after compiling
            raised = "" if "invalid device ordinal" in str(e) else f"{type(e).__name__}: {e}"
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        err.seek(0)
        errors = [line for line in err.read().splitlines() if "error:" in line]
    return errors, raised[:500]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", nargs="*", help="these CASES names")
    ap.add_argument("--n", type=int, default=300, help="Gaussians of the random scene")
    args = ap.parse_args(argv)
    os.environ.setdefault("CUDA_VISIBLE_DEVICES", "-1")
    import jax

    jax.config.update("jax_platforms", "cpu")  # the GPU is only a compilation target
    jax.config.update("jax_enable_x64", True)  # as tests/conftest.py: the float64 cases
    sharding = target_device(CUB_DEVICE)
    table = cases()
    bad = 0
    for name in args.only or table:
        errors, raised = build(*table[name], args.n, sharding)
        bad += bool(errors or raised)
        print(f"{name:<14} {'FAILED' if errors or raised else 'built'}", flush=True)
        for line in errors[:6] + ([raised] if raised else []):
            print(f"    {line[:300]}", flush=True)
    print(f"{len(args.only or table) - bad} built, {bad} failed")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
