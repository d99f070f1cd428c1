"""XLA's memory for a `benchmarks.scale` row on an NVIDIA H200, compiled on a machine without a GPU.

    build/gpu-offline/bin/python scripts/gpu_memory_offline.py SCENE [--grad] [--row localgs]
        [--capacity C] [--rows R|none] [--data DIR] [--dump DIR [--top 30]]
        [--tuning NAME=VALUE ...]

JAX compiles for a GPU it does not have ("deviceless" compilation:
`jax.experimental.topologies.get_topology_desc(platform="cuda", target_config=...)`), given a
target description (`TARGET`: the H200's SMs, memory and compute capability 9.0). XLA runs its
whole GPU pipeline (fusion, scheduling, buffer assignment), the Pallas kernels lowered for the
GPU (Mosaic GPU and Triton: `KernelConfig.interpret` is forced False), so the buffers are the
GPU's: on Dec 3 the 10M/4K gradient with walked rows gave 1616.3 MiB here and 1616 MiB on the
H200, and `scripts/hlo_peak.py` the same peak (BENCHMARKS.md §7, Dec 3, fourth session).
Nothing runs, so there are no times.

Needs a separate environment with JAX's CUDA plugin (4.5 GB; not a project dependency):

    PYENV_VERSION=3.12.1 python3.12 -m venv build/gpu-offline
    build/gpu-offline/bin/pip install ".[gpu]"   # the package's gpu extra: jax[cuda13]

Two details of the plugin shape the target: XLA sorts with CUB only for devices in its bundled
table of CUB scratch sizes, which has the H100 but not the H200, so the target is named "NVIDIA
H100 80GB HBM3" (same SMs and compute capability; `--device-name` overrides, and with a name
the table lacks XLA uses its own sort and other buffers). With CUB sorts XLA completes buffer
assignment and then fails to build the executable without a device ("invalid device
ordinal"), so the memory is summed from the dump's buffer assignment (temporaries + outputs,
what `compiled.memory_analysis()` reports where it works). Pallas' Triton lowering asks JAX's
default device for its kind, so that is patched to the target's.

Prints the memory (temporaries + outputs, as `benchmarks.scale`'s "mem") and, with `--dump`,
hlo_peak's live values at the peak (with `--temp`: of the temporary allocation alone, which is
what sets its size).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import glob
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CUB_DEVICE = "NVIDIA H100 80GB HBM3"  # in XLA's deviceless CUB table; the H200 is not
TARGET = """
gpu_device_info {
  threads_per_block_limit: 1024 threads_per_warp: 32 shared_memory_per_block: 49152
  shared_memory_per_core: 233472 threads_per_core_limit: 2048 core_count: 132
  fpus_per_core: 128 block_dim_limit_x: 2147483647 block_dim_limit_y: 65535
  block_dim_limit_z: 65535 memory_bandwidth: 4800000000000 l2_cache_size: 52428800
  clock_rate_ghz: 1.98 device_memory_size: 150754820096 shared_memory_per_block_optin: 232448
  cuda_compute_capability { major: 9 minor: 0 }
  registers_per_core_limit: 65536 registers_per_block_limit: 65536 cub_version: "3.1.2"
}
platform_name: "CUDA"
dnn_version_info { major: 9 minor: 8 }
runtime_version { major: 12 minor: 9 patch: 0 }
device_description_str: "%s"
"""


def target_device(name: str):
    """The one device of a deviceless H200 topology (Triton lowering patched to see it)."""
    import jax
    from jax._src.pallas.triton import gpu_info
    from jax.experimental import topologies

    topology = topologies.get_topology_desc(platform="cuda", target_config=TARGET % name,
                                            topology="1x1x1")
    device = topology.devices[0]
    gpu_info.get_device_kind = lambda: device.device_kind
    return jax.sharding.SingleDeviceSharding(device)


def program(args, sharding):
    """(jitted function, abstract arguments): the row's render (its image, or with --grad the
    value and gradient of Σ image·w over every field) of the scene at its pair capacity."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import lgs_jax
    from benchmarks import common, scale

    g, cam = common.load_scene(args.scene, args.data)
    capacity = args.capacity or lgs_jax.pair_capacity(scale.count_pairs(g, cam))
    rows = None if args.rows == "none" else int(args.rows)
    backend, config = scale.ROWS[args.row]
    tuning = dict(interpret=False, **{k: ast.literal_eval(v) for k, v in
                                      (item.split("=", 1) for item in args.tuning)})
    config = dataclasses.replace(config, tuning=dataclasses.replace(config.tuning, **tuning))
    cam = jax.tree.map(np.asarray, cam)
    print(f"{args.scene}: {g.num} Gaussians, {cam.width}x{cam.height}, row {args.row}, "
          f"capacity {capacity}, row_capacity {rows}", flush=True)

    def image(g):
        return lgs_jax.render(g, cam, backend=backend, config=config, capacity=capacity,
                              row_capacity=rows).image

    def loss(g, w):
        return jnp.sum(image(g) * w)

    abstract = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding),
                            g)
    if not args.grad:
        return jax.jit(image), (abstract,)
    w = jax.ShapeDtypeStruct((cam.height, cam.width, 3), jnp.float32, sharding=sharding)
    return jax.jit(jax.value_and_grad(loss)), (abstract, w)


def assigned_mib(prefix: str) -> tuple[float, float]:
    """(temporaries, outputs) in MiB: the allocations of a buffer-assignment dump, parameters
    and constants left out."""
    temp = out = 0
    for line in open(prefix + "-buffer-assignment.txt"):
        if not line.startswith("allocation ") or "parameter" in line or "constant" in line:
            continue
        size = int(line.split("size ")[1].split(",")[0])
        out, temp = (out + size, temp) if "maybe-live-out" in line else (out, temp + size)
    return temp / 2**20, out / 2**20


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="a benchmarks.common.SCENES name, e.g. guitar_x110_4k")
    ap.add_argument("--grad", action="store_true", help="forward + backward (else the forward)")
    ap.add_argument("--row", default="localgs", help="a benchmarks.scale.ROWS key")
    ap.add_argument("--capacity", type=int, help="pair capacity (default: counted on the CPU)")
    ap.add_argument("--rows", default="none", help="render's row_capacity, or none")
    ap.add_argument("--data", default=os.path.join(ROOT, "..", "shared", "data"))
    ap.add_argument("--device-name", default=CUB_DEVICE)
    ap.add_argument("--dump", help="XLA dump folder: then hlo_peak.py's peak is printed too")
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--temp", action="store_true", help="hlo_peak.py --temp")
    ap.add_argument("--tuning", action="append", default=[], metavar="NAME=VALUE",
                    help="a KernelConfig field for the row, e.g. backward_segment=2048")
    args = ap.parse_args(argv)
    os.environ.setdefault("CUDA_VISIBLE_DEVICES", "-1")
    dump = os.path.abspath(args.dump or os.path.join(ROOT, "build", "gpu-offline-dump"))
    os.environ["XLA_FLAGS"] = (f"{os.environ.get('XLA_FLAGS', '')} --xla_dump_to={dump} "
                               "--xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*(loss|image).*")
    sys.path.insert(0, ROOT)
    import jax

    jax.config.update("jax_platforms", "cpu")  # the GPU is only a compilation target
    f, abstract = program(args, target_device(args.device_name))
    start = time.time()
    try:
        f.lower(*abstract).compile()
    except Exception as e:  # noqa: BLE001 - with CUB sorts XLA fails after buffer assignment
        print(f"(no executable without a device: {type(e).__name__}: {str(e)[:300]})", flush=True)
    new = [p for p in glob.glob(f"{dump}/*after_optimizations-buffer-assignment.txt")
           if os.path.getmtime(p) >= start]
    if not new:
        print(f"no new buffer assignment in {dump}")
        return 1
    prefix = max(new, key=os.path.getmtime).removesuffix("-buffer-assignment.txt")
    temp, out = assigned_mib(prefix)
    print(f"memory: temporaries {temp:.1f} + outputs {out:.1f} = {temp + out:.1f} MiB", flush=True)
    if args.dump:
        extra = ["--temp"] if args.temp else []
        subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "hlo_peak.py"), prefix,
                        "--top", str(args.top), *extra], check=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
