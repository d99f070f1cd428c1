"""One process of tests/parallel/test_gaussian_parallel_multihost.py's training runs: `fit` of
the tiny capture (`tiny_run`) with its Gaussians split over 4 simulated CPU devices, either of
two processes of 2 devices each joined by `jax.distributed.initialize` (gloo collectives), or
one process of 4 (the reference).

    python -m tests.parallel.multihost_fit_child PROCESS PORT OUT PART  # PROCESS 0 or 1 of two
    python -m tests.parallel.multihost_fit_child one 0 OUT PART         # one process, 4 devices

PART "fast": trained on every view (nothing held out, no evaluation to compile); "slow": view
0 held out and evaluated at the end.

Process i trains into OUT/p<i> (the reference into OUT/one), its log lines in OUT/log<i>.json:
every process makes the same call but for its folder, so that the parent sees what each
writes."""

import json
import os
import sys

ONE = sys.argv[1] == "one"
os.environ["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={4 if ONE else 2}"
os.environ["JAX_PLATFORMS"] = "cpu"

import dataclasses  # noqa: E402

import jax  # noqa: E402

jax.config.update("jax_cpu_collectives_implementation", "gloo")

if os.environ.get("LGS_JAX_CACHE"):
    from lgs_jax.cli import cache_into  # noqa: E402

    cache_into(os.environ["LGS_JAX_CACHE"], least_seconds=0.5)

from lgs_jax import train  # noqa: E402
from tests.parallel.tiny_run import capture, config  # noqa: E402

STEPS = 4  # a refinement at step 3


def main(process: str, port: int, out: str, part: str):
    if not ONE:
        jax.distributed.initialize(coordinator_address=f"localhost:{port}", num_processes=2,
                                   process_id=int(process))
        assert jax.device_count() == 4 and jax.local_device_count() == 2
    name = "one" if ONE else f"p{process}"
    logs = []
    run = dataclasses.replace(config(os.path.join(out, name), jax.device_count(),
                                     train_on_all=part == "fast"), steps=STEPS)
    train.fit(run, capture(os.path.join(out, "data")), log=logs.append)
    with open(os.path.join(out, f"log{process}.json"), "w") as f:
        json.dump(logs, f)
    if not ONE:
        jax.distributed.shutdown()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4])
