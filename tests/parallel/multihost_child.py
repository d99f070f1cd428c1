"""One of two processes of tests/parallel/test_gaussian_parallel_multihost.py: JAX on 2
simulated CPU devices per process, joined by `jax.distributed.initialize` (gloo collectives)
into one mesh of 4; renders the sharded scene, and process 0 saves it with its own one-device
render (`python -m tests.parallel.multihost_child PROCESS PORT OUT.npz`)."""

import os
import sys

os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
os.environ["JAX_PLATFORMS"] = "cpu"

import jax  # noqa: E402
import numpy as np  # noqa: E402

jax.config.update("jax_cpu_collectives_implementation", "gloo")

import lgs_jax  # noqa: E402
from lgs_jax import parallel  # noqa: E402
from tests import scenes  # noqa: E402

W, H, N, CAPACITY, EXCHANGE = 40, 72, 37, 512, 32


def main(process: int, port: int, path: str):
    jax.distributed.initialize(coordinator_address=f"localhost:{port}", num_processes=2,
                               process_id=process)
    assert jax.device_count() == 4 and jax.local_device_count() == 2
    dtype = np.float32
    g, cam = scenes.scene(3, n=N, dtype=dtype), scenes.camera(W, H, dtype=dtype)
    bg = np.asarray(scenes.BACKGROUND, dtype)
    mesh = parallel.gaussian_mesh(4)
    shards = parallel.shard_gaussians(g, mesh)
    out = jax.jit(lambda gs, c, bg: parallel.render_sharded(
        parallel.GaussianShards(gs, N), c, mesh, background=bg, backend="tiles",
        capacity=CAPACITY, exchange_capacity=EXCHANGE))(shards.gaussians, cam, bg)
    res = {k: parallel.to_host(getattr(out, k)) for k in ("image", "alpha", "depth")}
    res["overflow"] = np.asarray([parallel.to_host(out.stats.overflow),
                                  parallel.to_host(out.stats.exchange_overflow)])
    back = parallel.gather_gaussians(shards)
    res["gathered"] = np.array_equal(back.means, g.means, equal_nan=True)
    if process == 0:
        local = jax.local_devices()[0]
        one = jax.jit(lambda g, c, bg: lgs_jax.render(g, c, background=bg, backend="tiles",
                                                      capacity=CAPACITY))
        ref = one(*jax.device_put((g, cam, bg), local))
        for k in ("image", "alpha", "depth"):
            res[f"one/{k}"] = np.asarray(getattr(ref, k))
        np.savez(path, **res)
    jax.distributed.shutdown()


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3])
