"""Run directories and checkpoints.

A run directory holds one run (`run_dir_problem`): a non-empty one needs resume (and a
checkpoint) or overwrite (the old run's files are deleted first). A checkpoint is
`checkpoint.npz` (every array of the pool, active mask and free slots included, of the
optimizer state and of the strategy state) plus `checkpoint.json` (step, pair capacities, pool
size, seed, skipped steps, and the run's configuration), written atomically (a temporary file,
then a rename). Resuming restores those bits exactly: with the same configuration, a resumed run
continues bit-identically to an uninterrupted one (views and random keys depend only on the step
and the seed). `scene.ply` beside it holds the active Gaussians.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re

import jax
import jax.numpy as jnp
import numpy as np

RUN_FILES = ("scene.ply", "checkpoint.npz", "checkpoint.json", "metrics.jsonl", "result.json",
             "curves.png", "cameras.json", "colors.json", "bilateral_grids.npz",
             "appearance.npz", "optimizer.npz")  # optimizer.npz: runs of the fixed-count trainer
PARTS = ("pool", "opt", "strategy", "views")  # views: `view_params`' state, None without it


def run_files(out: str) -> list[str]:
    """The files a run wrote into `out`: RUN_FILES and the held-out renders."""
    return [n for n in os.listdir(out)
            if n in RUN_FILES or re.fullmatch(r"heldout_.+\.png", n)]


def run_dir_problem(out: str, resume: bool = False, overwrite: bool = False) -> str | None:
    """Why the run directory `out` cannot take this run, or None if it can.

    A new or empty directory always can; one holding files needs `resume` (and a checkpoint to
    resume from) or `overwrite` (its previous run's files are deleted), so two runs never mix.
    """
    if resume and overwrite:
        return "resume and overwrite exclude each other"
    if os.path.exists(out) and not os.path.isdir(out):
        return f"{out} exists and is not a directory"
    if not os.path.isdir(out) or not os.listdir(out) or overwrite:
        return None
    if resume:
        if os.path.exists(os.path.join(out, "checkpoint.json")):
            return None
        return f"{out} holds files but no checkpoint.json to resume from"
    return (f"{out} is not empty (it holds {', '.join(sorted(os.listdir(out))[:3])}, ...); "
            "pass --resume (resume=True) to continue its run or --overwrite (overwrite=True) "
            "to replace it")


def config_of(setup, seed: int) -> dict:
    """The configuration a resumed run must share with the saved one (all but the run length,
    the backend, the evaluation/checkpoint periods, the pair and row headrooms, the images'
    streaming: none changes a result)."""
    settings = dataclasses.asdict(setup.settings)
    for k in ("eval_every", "checkpoint_every", "pair_headroom", "row_headroom",
              "stream_images"):
        settings.pop(k)
    return dict(strategy=type(setup.strategy).__name__,
                strategy_settings=dataclasses.asdict(setup.strategy), settings=settings,
                seed=seed)


def save(out: str, state: tuple, meta: dict) -> None:
    """Write (pool, opt_state, strategy_state, views) and `meta` (json-able) as the
    checkpoint."""
    arrays = {f"{name}_{i}": np.asarray(x) for name, part in zip(PARTS, state)
              for i, x in enumerate(jax.tree.leaves(part))}
    tmp = os.path.join(out, "checkpoint.tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, os.path.join(out, "checkpoint.npz"))
    with open(os.path.join(out, "checkpoint.tmp.json"), "w") as f:
        json.dump(meta, f, indent=1)
    os.replace(os.path.join(out, "checkpoint.tmp.json"), os.path.join(out, "checkpoint.json"))


def read_meta(out: str) -> dict:
    """checkpoint.json; ValueError for a checkpoint this version cannot resume."""
    with open(os.path.join(out, "checkpoint.json")) as f:
        meta = json.load(f)
    if "config" not in meta or not os.path.exists(os.path.join(out, "checkpoint.npz")):
        raise ValueError(f"resume: {out} holds a checkpoint of an older lgs_jax.train (no "
                         "checkpoint.npz); start a new run (--overwrite)")
    return meta


def restore(out: str, templates: tuple) -> tuple:
    """(pool, opt_state, strategy_state, views) from the checkpoint, shaped like `templates`
    (the same structures at the saved pool size)."""
    saved = np.load(os.path.join(out, "checkpoint.npz"))
    parts = []
    for name, template in zip(PARTS, templates):
        leaves, treedef = jax.tree.flatten(template)
        parts.append(jax.tree.unflatten(
            treedef, [jnp.asarray(saved[f"{name}_{i}"]) for i in range(len(leaves))]))
    return tuple(parts)


def config_mismatch(saved: dict, current: dict, defaults: dict | None = None) -> str | None:
    """A sentence naming what differs between a checkpoint's configuration and this run's, or
    None. `defaults` (`config_of` a setup of default settings and strategy): a setting or
    strategy field the saved configuration lacks (it was written before the field existed)
    counts as its default."""
    for k, fields in (defaults or {}).items():
        if isinstance(fields, dict) and isinstance(saved.get(k), dict):
            saved = dict(saved, **{k: {**fields, **saved[k]}})
    if saved == current:
        return None
    diff = []
    for k in current:
        if isinstance(current[k], dict) and isinstance(saved.get(k), dict):
            diff += [f"{k}.{f}: {saved[k].get(f)!r} -> {v!r}" for f, v in current[k].items()
                     if saved[k].get(f) != v]
        elif saved.get(k) != current[k]:
            diff.append(f"{k}: {saved.get(k)!r} -> {current[k]!r}")
    return "the checkpoint was made with other settings (" + "; ".join(diff) + ")"
