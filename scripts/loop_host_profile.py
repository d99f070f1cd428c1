"""Where the host's time goes in `fit`'s loop: each part of a step timed on the calling thread.

    python scripts/loop_host_profile.py [--data-root carry/data] [--scene lego] [--steps 2000]
        [--eval-every N] [--stream | --no-stream] [--downscale K] [--xla-flags="FLAGS"]

Runs `benchmarks.train_vs_gsplat`'s run of SCENE (MCMC, its cap and start) for STEPS steps twice:
seed 0 fills the persistent compilation cache and the export entries (its compiles are not the
question), then seed 1 is timed, its loop's functions wrapped (`PARTS`): for each, the calls,
microseconds per call and milliseconds per step. `_one_step` is a whole step on the host (the
dispatch of the next, the read of this one's metrics); `stepper.run`, the call of the step's
executable, in which XLA enqueues the step's kernels (the held-out evaluations' programs
run through it too); `read_metrics`, the read of the metrics,
which includes the wait for the device (result.json's `device_wait_seconds`, printed beside).
--xla-flags adds XLA flags (to XLA_FLAGS, before JAX starts) for the question whether one
changes the host's time, e.g. XLA's command buffers (CUDA graphs) off:
`--xla-flags=--xla_gpu_enable_command_buffer=`; the persistent cache keys on them, so a
variant's seed 0 compiles.
A part under the others (`signature` under `_dispatch`) counts in both. Nothing here changes a
bit of the run. The parts are private functions of `lgs_jax.train.loop` and its collaborators,
wrapped by name: a renamed one fails here by name.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import functools
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

# (module, attribute path, label) of the parts timed
PARTS = (
    ("lgs_jax.train.loop", "_one_step", "_one_step"),
    ("lgs_jax.train.loop", "_dispatch", "_dispatch"),
    ("lgs_jax.train.loop", "read_metrics", "read_metrics (incl. the wait)"),
    ("lgs_jax.train.loop", "signature", "signature"),
    ("lgs_jax.train.loop", "_after_step", "_after_step"),
    ("lgs_jax.train.loop", "_refine", "_refine"),
    ("lgs_jax.train.ahead", "Stepper.run", "stepper.run (launch)"),
    ("lgs_jax.train.ahead", "Stepper.prepare", "stepper.prepare"),
    ("lgs_jax.train.levels", "LevelFeed.args", "feed.args"),
    ("lgs_jax.train.levels", "LevelFeed.prefetch", "feed.prefetch"),
    ("lgs_jax.train.report", "Progress.step", "progress"),
    ("lgs_jax.train.report", "PeakRise.__call__", "peak"),
    ("lgs_jax.train.heldout", "Evaluations.score", "evaluation"),
)


def timed(parts=PARTS):
    """Wrap `parts`; returns (seconds, calls) per label, filled as the wrapped functions run."""
    import importlib

    seconds, calls = collections.defaultdict(float), collections.Counter()
    for module, path, label in parts:
        owner = importlib.import_module(module)
        *outer, name = path.split(".")
        for attr in outer:
            owner = getattr(owner, attr)
        fn = getattr(owner, name)

        def wrapper(*args, _fn=fn, _label=label, **kwargs):
            t0 = time.perf_counter()
            try:
                return _fn(*args, **kwargs)
            finally:
                seconds[_label] += time.perf_counter() - t0
                calls[_label] += 1

        setattr(owner, name, functools.wraps(fn)(wrapper))
    return seconds, calls


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data-root", default=os.path.join(ROOT, "..", "shared", "data"))
    ap.add_argument("--scene", default="lego", help="a benchmarks.train_vs_gsplat SCENES name")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--eval-every", type=int, default=10**9, help="default: no evaluation")
    ap.add_argument("--downscale", type=int, help="image downscale (default: the scene's)")
    ap.add_argument("--stream", action=argparse.BooleanOptionalAction, default=None,
                    help="stream the training images (default: fit's: on a GPU)")
    ap.add_argument("--xla-flags", default="", help="more XLA flags (module docstring)")
    args = ap.parse_args(argv)
    if args.xla_flags:
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {args.xla_flags}".strip()
    from benchmarks import train_vs_gsplat as tv
    from lgs_jax import cli
    from lgs_jax.train import fit

    cli.use_compile_cache()
    seconds, calls = timed()
    bench = tv.parse(["--data-root", args.data_root, "--scenes", args.scene, "--steps",
                      str(args.steps), "--eval-every", str(args.eval_every)]
                     + (["--downscale", str(args.downscale)] if args.downscale else []))
    data, config = tv.scene_setup(bench, args.scene, os.path.join("/tmp", "loop_host_profile"))
    for seed in (0, 1):
        seconds.clear()
        calls.clear()
        result = fit(dataclasses.replace(config, seed=seed, stream_images=args.stream), data,
                     log=lambda *_: None)
    steps = max(calls["_one_step"], 1)
    waited, busy = result["device_wait_seconds"], result["step_seconds"]
    print(f"XLA_FLAGS: {os.environ.get('XLA_FLAGS', '')!r}")
    print(f"{args.scene}, seed 1, {steps} steps: {1e3 * busy / steps:.3f} ms a step, "
          f"compiling {result['compile_seconds']:.1f} s, waiting for the device {waited:.2f} of "
          f"{busy:.2f} s")
    print(f"{'part':26s} {'calls':>6s} {'us a call':>10s} {'ms a step':>10s}")
    for label in sorted(seconds, key=seconds.get, reverse=True):
        print(f"{label:26s} {calls[label]:6d} {1e6 * seconds[label] / calls[label]:10.1f} "
              f"{1e3 * seconds[label] / steps:10.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
