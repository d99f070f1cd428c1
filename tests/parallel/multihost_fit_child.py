"""One process of tests/parallel/test_gaussian_parallel_multihost.py's runs of `fit` over
several processes: two processes of 2 simulated CPU devices each, joined by
`jax.distributed.initialize` (gloo collectives) into one mesh of 4, or one process of 4 (the
reference).

    python -m tests.parallel.multihost_fit_child PROCESS PORT OUT PART  # PROCESS 0 or 1 of two
    python -m tests.parallel.multihost_fit_child one 0 OUT fit          # one process, 4 devices

PART "fit": `fit` of the tiny capture (`tiny_run`, view 0 held out) with its Gaussians split
over the 4 devices; process i trains into OUT/p<i> (the reference into OUT/one), its log lines
in OUT/log<i>.json: every process makes the same call but for its folder, so that the parent
sees what each writes. PART "resume": the "fit" run continued to `RESUMED` steps (`resume`),
every process on process 0's folder OUT/p0 (the reference on OUT/one), its log lines in
OUT/resumed<i>.json. PART "seam": no training; what the processes read (`parallel.to_host`)
and what they refuse (`train.processes`, `fit`'s checks), each process's findings in
OUT/seam<i>.json."""

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

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from jax.sharding import NamedSharding, PartitionSpec  # noqa: E402

from lgs_jax import parallel, train  # noqa: E402
from lgs_jax.train import processes  # noqa: E402
from tests.parallel.tiny_run import capture, config  # noqa: E402

STEPS = 4  # a refinement at step 3
RESUMED = 7  # resumed after STEPS: a refinement at step 6


def _refusal(fn) -> str | None:
    """The message of the `ValueError` fn() raises, or None."""
    try:
        fn()
    except ValueError as e:
        return str(e)
    return None


def seam(process: int, out: str) -> dict:
    """What process `process` reads and refuses (module docstring)."""
    mesh = parallel.gaussian_mesh(4)
    rows = np.arange(8.0, dtype=np.float32)
    split = jax.make_array_from_callback((8,), parallel.gaussian_sharding(mesh),
                                         lambda i: rows[i])
    total = jax.jit(jnp.sum, out_shardings=NamedSharding(mesh, PartitionSpec()))(split)
    read = parallel.to_host(dict(split=split, total=total, host=rows[:2]))
    found = dict(split=read["split"].tolist(), total=float(read["total"]),
                 host=read["host"].tolist(), writer=processes.writer(),
                 total_replicated=bool(total.is_fully_replicated))
    base = config(os.path.join(out, "refused"), 4, train_on_all=True)
    data = capture(os.path.join(out, "data"))
    for name, kwargs in (("two", dict(gaussian_devices=2)), ("rows", dict(devices=2, recipe=(
            dataclasses.replace(base.recipe, batch=2)), gaussian_devices=2))):
        found[name] = _refusal(lambda: train.fit(dataclasses.replace(base, **kwargs), data))
    found["watch"] = _refusal(lambda: train.fit(base, data, watch=lambda *_: None))
    # a folder that process 0 refuses (it holds a file, no resume): every process raises
    busy = os.path.join(out, "busy")
    if process == 0:
        os.makedirs(busy)
        open(os.path.join(busy, "other.txt"), "w").close()
    processes.synced("busy made")
    found["busy"] = _refusal(lambda: train.fit(dataclasses.replace(base, out=busy), data))
    return found


def main(process: str, port: int, out: str, part: str):
    if not ONE:
        jax.distributed.initialize(coordinator_address=f"localhost:{port}", num_processes=2,
                                   process_id=int(process))
        assert jax.device_count() == 4 and jax.local_device_count() == 2
    if part == "seam":
        with open(os.path.join(out, f"seam{process}.json"), "w") as f:
            json.dump(seam(int(process), out), f)
        jax.distributed.shutdown()
        return
    resume = part == "resume"
    name = "one" if ONE else "p0" if resume else f"p{process}"
    logs = []
    run = dataclasses.replace(config(os.path.join(out, name), jax.device_count()),
                              steps=RESUMED if resume else STEPS, resume=resume)
    train.fit(run, capture(os.path.join(out, "data")), log=logs.append)
    with open(os.path.join(out, f"{'resumed' if resume else 'log'}{process}.json"), "w") as f:
        json.dump(logs, f)
    if not ONE:
        jax.distributed.shutdown()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4])
