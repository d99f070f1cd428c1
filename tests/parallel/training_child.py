"""The child process of tests/parallel/test_gaussian_parallel_training.py: `fit` with the
Gaussians split over 1, 2 and 4 simulated CPU devices (`--xla_force_host_platform_device_count`,
set before JAX starts), on a synthetic capture made here (`capture`), each run's folder left
under OUT for the parent to compare (`python -m tests.parallel.training_child OUT`). OUT/logs.json
holds what the folders cannot: each run's log lines.

The runs (`RUNS`): the same run on 1, 2 and 4 devices; on 4 devices again from pair and
exchange buffers sized at the first view's needs exactly (they overflow and grow); on 4 devices
stopped (Ctrl-C) after step `HALF`, then resumed on 2. Few compiles (each costs seconds on a
CPU): the runs share one configuration but for their device count and buffers, and the stopped
run finds its step compiled by the full run on 4 devices."""

import json
import os
import shutil
import signal
import sys

os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402
import numpy as np  # noqa: E402

if os.environ.get("LGS_JAX_CACHE"):
    jax.config.update("jax_compilation_cache_dir", os.environ["LGS_JAX_CACHE"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

import lgs_jax  # noqa: E402
from lgs_jax import train  # noqa: E402
from lgs_jax.io.datasets import Dataset  # noqa: E402

W, H = 32, 64  # 2 x 4 tiles: a band of one tile row per device on 4 devices
VIEWS = 5  # view 0 held out
POINTS = 301  # blocks of 151 + 150 on 2 devices, 76 + 3 x 75 on 4: uneven shards
POOL = 302  # 304 slots on 4 devices (padded to equal blocks)
STEPS, HALF = 8, 4
# refinements at steps 3 and 6, clones only (no split: grow_scale3d beyond any Gaussian), and
# prunes: the parameters' differences across device counts stay within `sharded.drift_bound`
STRATEGY = train.DefaultStrategy(refine_start_iter=2, refine_every=3, grow_grad2d=1e-4,
                                 prune_opa=0.02, grow_scale3d=100.0)
RUNS = ("d1", "d2", "d4", "d4_grown", "d4_stopped", "d4_resumed_on_d2")


def capture(path: str) -> Dataset:
    """`VIEWS` cameras on an arc 3 units from a box of `POINTS` coloured points, photos of
    smooth random colour waves (the same capture every call)."""
    rng = np.random.default_rng(0)
    cams, images = [], []
    y, x = np.mgrid[0:H, 0:W] / np.float32(H)
    for i in range(VIEWS):
        a = 0.15 * (i - VIEWS // 2)
        c, s = np.cos(a), np.sin(a)
        view = np.eye(4)
        view[:3, :3] = [[c, 0, -s], [0, 1, 0], [s, 0, c]]
        view[:3, 3] = [0.0, 0.0, 3.0]
        cams.append(lgs_jax.Camera(viewmat=view.astype(np.float32), fx=np.float32(40),
                                   fy=np.float32(40), cx=np.float32(W / 2),
                                   cy=np.float32(H / 2), width=W, height=H))
        f = rng.uniform(2, 6, 3)
        images.append(0.5 + 0.4 * np.sin(f * (x[..., None] + y[..., None] + a) + rng.uniform(
            0, 6, 3)))
    points = rng.uniform(-0.6, 0.6, (POINTS, 3)).astype(np.float32)
    points[:, 1] *= 2  # the image is twice as high as wide
    return Dataset(path=path, names=tuple(f"v{i}.png" for i in range(VIEWS)),
                   images=np.stack(images).astype(np.float32), cameras=tuple(cams),
                   points=points, colors=rng.uniform(0, 1, (POINTS, 3)).astype(np.float32),
                   train=np.arange(1, VIEWS), test=np.arange(1), background=np.zeros(3, np.float32))


def config(out: str, devices: int, **kwargs) -> train.FitConfig:
    """The runs' configuration on `devices` devices (kwargs: other fields)."""
    return train.FitConfig(data=out, out=out, steps=STEPS, strategy=STRATEGY,
                           recipe=train.Recipe(batch=2), max_gaussians=1000, pool_size=POOL,
                           backend="reference", gaussian_devices=devices, eval_every=100,
                           checkpoint_every=100, **kwargs)


def main(out: str):
    data = capture(os.path.join(out, "data"))
    logs = {name: [] for name in RUNS}
    where = lambda name: os.path.join(out, name)
    for name, devices in (("d1", 1), ("d2", 2), ("d4", 4)):
        train.fit(config(where(name), devices), data, log=logs[name].append)
    train.fit(config(where("d4_grown"), 4, pair_headroom=1.0), data,
              log=logs["d4_grown"].append)
    stop = lambda step, *_: step == HALF and os.kill(os.getpid(), signal.SIGINT)
    try:
        train.fit(config(where("d4_stopped"), 4), data, log=logs["d4_stopped"].append,
                  watch=stop, watch_every=0)
    except train.Interrupted:
        pass
    shutil.copytree(where("d4_stopped"), where("d4_resumed_on_d2"))
    train.fit(config(where("d4_resumed_on_d2"), 2, resume=True), data,
              log=logs["d4_resumed_on_d2"].append)
    with open(os.path.join(out, "logs.json"), "w") as f:
        json.dump(logs, f)


if __name__ == "__main__":
    main(sys.argv[1])
