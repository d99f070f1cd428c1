"""XLA's memory for a `benchmarks.scale` row on an NVIDIA H200, or for `fit`'s training step,
compiled on a machine without a GPU.

    build/gpu-offline/bin/python scripts/gpu_memory_offline.py SCENE [--grad] [--row localgs]
        [--capacity C] [--rows R|none] [--data DIR] [--dump DIR] [--top 30]
        [--tuning NAME=VALUE ...]
    build/gpu-offline/bin/python scripts/gpu_memory_offline.py --train-step DATA_DIR
        --gaussians N --pool P --capacity C --rows R [--top 30]

The training step (`--train-step`): `train.step.train_step` as `fit` runs it with MCMC and one
view a step, on DATA_DIR's first training view, with N Gaussians in a pool of P slots
(`profile_train_step.densified_pool`), at pair capacity C and R backward rows; JAX's default
backend reads as "gpu" to the package, so that it takes its GPU paths (compiled kernels, the
fused SSIM). Its temporaries plus the state in use between steps (`fit`'s `mib_in_use`) give
a run's peak at that capacity: fox at 6.8M slots, 366.2 + 480.6 = 846.8 MiB, the H100's
measured peak to the tenth.

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

Prints the memory (temporaries + outputs, as `benchmarks.scale`'s "mem") and the `--top`
largest values of the temporary allocation (each with its offset there: values at overlapping
offsets are never live together).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import glob
import os
import sys
import time
import types

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


def train_step_program(args, sharding):
    """(jitted function, abstract arguments): `fit`'s training step (module docstring)."""
    import jax
    import jax.numpy as jnp

    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    from profile_train_step import densified_pool
    from lgs_jax.train import MCMCStrategy, Recipe, Setup
    from lgs_jax.train.feed import prepare
    from lgs_jax.train.step import train_step

    rd = prepare(args.train_step, 1, dtype="auto")
    setup = Setup(Recipe(), MCMCStrategy(cap_max=args.pool), 7000, rd.scene_scale, "pallas")
    _, (pool, opt, strategy) = densified_pool(rd, setup, args.gaussians, args.pool)
    jax.default_backend = lambda: "gpu"  # the package's GPU paths (module docstring)
    rows = None if args.rows == "none" else int(args.rows)
    print(f"{args.train_step}: {args.gaussians} Gaussians in {args.pool} slots, capacity "
          f"{args.capacity}, rows {rows}", flush=True)
    shaped = lambda tree: jax.tree.map(
        lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding), tree)
    targets = jnp.asarray(rd.train_images[:1])  # as stored: the step converts them
    abstract = shaped((pool, opt, strategy, None, rd.train_cams, targets, jnp.array([0]),
                       jnp.asarray(rd.background), jnp.int32(6000), jax.random.key(0)))
    static = dict(setup=setup, capacity=args.capacity, rows=rows)  # jitted as fit's, donating
    return types.SimpleNamespace(lower=lambda *a: train_step.lower(*a, **static)), abstract


def largest(prefix: str, top: int) -> list[tuple[int, int, str]]:
    """(bytes, offset, value and shape) of the `top` largest values in the dump's temporary
    allocation."""
    values, inside = [], False
    for line in open(prefix + "-buffer-assignment.txt"):
        if line.startswith("allocation "):
            inside = "preallocated-temp" in line
        elif inside and line.lstrip().startswith("value:"):
            name = line.split("<")[1].split(">")[0].split()[1]
            size = int(line.split("size=")[1].split(",")[0])
            offset = int(line.split("offset=")[1].split(")")[0])
            values.append((size, offset, f"{name} {line.rsplit(': ', 1)[1].strip()}"))
    return sorted(values, reverse=True)[:top]


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
    ap.add_argument("scene", nargs="?", help="a benchmarks.common.SCENES name, e.g. "
                    "guitar_x110_4k")
    ap.add_argument("--train-step", metavar="DATA_DIR", help="fit's training step instead")
    ap.add_argument("--gaussians", type=int, default=100_000)
    ap.add_argument("--pool", type=int, default=300_000)
    ap.add_argument("--grad", action="store_true", help="forward + backward (else the forward)")
    ap.add_argument("--row", default="localgs", help="a benchmarks.scale.ROWS key")
    ap.add_argument("--capacity", type=int, help="pair capacity (default: counted on the CPU)")
    ap.add_argument("--rows", default="none", help="render's row_capacity, or none")
    ap.add_argument("--data", default=os.path.join(ROOT, "..", "shared", "data"))
    ap.add_argument("--device-name", default=CUB_DEVICE)
    ap.add_argument("--dump", help="XLA dump folder (default build/gpu-offline-dump)")
    ap.add_argument("--top", type=int, default=0, help="list the largest temporaries")
    ap.add_argument("--tuning", action="append", default=[], metavar="NAME=VALUE",
                    help="a KernelConfig field for the row, e.g. backward_segment=2048")
    args = ap.parse_args(argv)
    if (args.scene is None) == (args.train_step is None):
        ap.error("give a SCENE or --train-step DATA_DIR")
    if args.train_step and args.capacity is None:
        ap.error("--train-step: give --capacity (and --rows)")
    os.environ.setdefault("CUDA_VISIBLE_DEVICES", "-1")
    dump = os.path.abspath(args.dump or os.path.join(ROOT, "build", "gpu-offline-dump"))
    os.environ["XLA_FLAGS"] = (f"{os.environ.get('XLA_FLAGS', '')} --xla_dump_to={dump} "
                               "--xla_dump_hlo_as_text "
                               "--xla_dump_hlo_module_re=.*(loss|image|step).*")
    sys.path.insert(0, ROOT)
    import jax

    jax.config.update("jax_platforms", "cpu")  # the GPU is only a compilation target
    make = train_step_program if args.train_step else program
    f, abstract = make(args, target_device(args.device_name))
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
    for size, offset, what in largest(prefix, args.top):
        print(f"  {size / 2**20:8.1f} MiB at {offset / 2**20:8.1f}  {what}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
