"""What a run leaves in OUT at its end (`finish`), each file written whole
(`lgs_jax.files.written`):
scene.ply (the active Gaussians, INRIA PLY), cameras.json (INRIA: the training cameras, at their
optimized poses with pose_opt, then the held-out ones), colors.json (with color_opt: each
training view's colour correction), bilateral_grids.npz (with bilateral_grid: each training
view's grid), appearance.npz (with app_opt: the features, embeddings and head,
`appearance.save`; scene.ply and the held-out renders are the scene at the views' average
appearance, `appearance.baked`), heldout_<name>.png (render beside ground truth), curves.png,
result.json; and the held-out evaluations (`evaluate`). On several processes every process
computes them and process 0 alone writes them (`processes.writer`)."""

from __future__ import annotations

import functools
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..io.cameras import save_cameras
from ..io.ply import save_ply
from ..parallel import to_host
from . import (appearance, bilateral_grid, camera_opt, color_opt, heldout, processes, report,
               sharded, sharded_state)
from .config import Setup
from .feed import RunData
from ..files import written
from .pool import active_gaussians
from .state import RunState, active_count, parts, scene
from .step import render_views


def evaluate(st: RunState, rd: RunData, setup: Setup, out: str | None = None,
             evaluations: heldout.Evaluations | None = None):
    """Held-out (PSNR, SSIM), (None, None) without held-out views; renders beside the ground
    truth written to `out` when given. `evaluations`: the run's, whose programs render the
    views (else `step.render_views`')."""
    if not rd.test_cams:
        return None, None
    if evaluations is not None:
        images = evaluations.images(scene(st))
        st.eval_capacity = evaluations.capacity
    else:
        render = render_views
        if setup.gaussian_devices > 1:
            render = functools.partial(sharded_state.render_views, sharded.mesh_of(setup))
        images, st.eval_capacity = render(scene(st), rd.test_cams, jnp.asarray(rd.background),
                                          setup.backend, st.eval_capacity, setup.recipe.raster)
    if out:
        report.save_renders(out, images, rd.test_images, rd.test_names)
    return report.heldout_metrics(images, rd.test_images)


def _cameras(st: RunState, rd: RunData) -> list:
    """The training cameras (at their optimized poses with `Recipe.pose_opt`), then the
    held-out ones."""
    cams = rd.train_cams
    if st.views is not None and "pose" in st.views:
        cams = camera_opt.adjusted(cams, to_host(st.views["pose"][0]))
    train = [rd.train_camera(i, cams) for i in range(len(rd.train_names))]
    return train + list(rd.test_cams)


def _views_files(out: str, st: RunState, rd: RunData) -> None:
    """appearance.npz, colors.json and bilateral_grids.npz of the views' own parameters (read
    on every process, written by `processes.writer`)."""
    views = to_host(st.views or {})
    if not processes.writer():
        return
    if "head" in views:
        keep = np.asarray(st.pool.active)
        with written(os.path.join(out, "appearance.npz")) as tmp:
            appearance.save(tmp, np.asarray(st.pool.params["features"])[keep],
                            views["embed"][0], jax.device_get(views["head"][0]), rd.train_names)
    if "color" in views:
        with written(os.path.join(out, "colors.json")) as tmp:
            color_opt.save(tmp, views["color"][0], rd.train_names)
    if "grid" in views:
        with written(os.path.join(out, "bilateral_grids.npz")) as tmp:
            bilateral_grid.save(tmp, views["grid"][0], rd.train_names)


def _compiling(run: dict) -> str:
    """The steps' compile time in words, with its parts and programs where `run` has them."""
    said = f"compiling {run['compile_seconds']:.1f} s"
    if "compile_parts" in run:
        names = dict(trace="tracing", lower="lowering", backend="XLA", waited="waiting")
        said += ": " + ", ".join(f"{names[k]} {v:.1f}" for k, v in run["compile_parts"].items())
        said += (f"; {run['programs_compiled']} programs compiled, {run['programs_loaded']} "
                 f"loaded from the cache")
    return said


def _waiting(run: dict) -> str:
    """The steps' wait for the device in words, where `run` has it: the loop thread blocked
    reading steps' metrics while the device computed (about the steps' time less compiling:
    the device is the bound; near zero: the host's Python is)."""
    if run.get("device_wait_seconds") is None:
        return ""
    return f"; waiting for the device {run['device_wait_seconds']:.1f} s"


def time_parts(run: dict) -> str:
    """The run's wall time in parts, in words (`fit`'s result: load_seconds, step_seconds and
    the compile_seconds within them, eval_seconds, checkpoint_seconds, finish_seconds)."""
    parts = [("loading and starting", "load_seconds"), ("steps", "step_seconds"),
             ("held-out evaluations", "eval_seconds"), ("checkpoints", "checkpoint_seconds"),
             ("final evaluation and outputs", "finish_seconds")]
    said = [f"{name} {run[key]:.1f} s" + (f" ({_compiling(run)}{_waiting(run)})"
                                          if key == "step_seconds" else "")
            for name, key in parts if run.get(key) is not None]
    return f"{run['seconds']:.1f} s in all: " + ", ".join(said)


def finish(out: str, setup: Setup, st: RunState, rd: RunData, run: dict, log,
           evaluations: heldout.Evaluations | None = None) -> dict:
    """The final evaluation (through `evaluations`, the run's, where given) and outputs
    (module docstring); returns the result: the steps done
    (fewer than the run's where the early stop ended it), held-out PSNR and SSIM, Gaussians,
    pool size, skipped steps, and `run` (the loop's times), with finish_seconds (this call's)
    added to its seconds; the time's parts are logged in a line."""
    t0, writes = time.perf_counter(), processes.writer()
    psnr, ssim = evaluate(st, rd, setup, out if writes else None, evaluations)
    if psnr is None:
        log(f"step {st.step}: no held-out views to evaluate (trained on every view)")
    else:
        with report.metrics_rows(out) as record:  # writes nothing on the other processes
            record(step=st.step, heldout_psnr=psnr, heldout_ssim=ssim)
        log(f"step {st.step}: held-out PSNR {psnr:.2f} dB, SSIM {ssim:.4f}")
    g, cams = active_gaussians(scene(st)), _cameras(st, rd)
    if writes:
        with written(os.path.join(out, "scene.ply")) as tmp:
            save_ply(tmp, g)
        with written(os.path.join(out, "cameras.json")) as tmp:
            save_cameras(tmp, cams, rd.train_names + rd.test_names)
    _views_files(out, st, rd)
    if writes:
        with written(os.path.join(out, "curves.png")) as tmp:
            report.plot_curves(report.read_metrics(os.path.join(out, "metrics.jsonl")), tmp)
    run = dict(run, finish_seconds=time.perf_counter() - t0)
    run["seconds"] += run["finish_seconds"]
    run["peak_mib"] = report.device_memory().get("peak_mib")
    run["memory"] = report.memory_parts(parts(st))
    log(time_parts(run))
    result = dict(steps=st.step, heldout_psnr=psnr, heldout_ssim=ssim,
                  gaussians=active_count(st.pool), pool_size=st.pool.size,
                  skipped_steps=st.skipped, **run,
                  strategy=type(setup.strategy).__name__, backend=setup.backend,
                  precision=setup.precision,
                  device=jax.devices()[0].device_kind, devices=setup.devices,
                  gaussian_devices=setup.gaussian_devices)
    if writes:
        with written(os.path.join(out, "result.json")) as tmp, open(tmp, "w") as f:
            json.dump(result, f, indent=1)
    return result
