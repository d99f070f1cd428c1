"""Checkpoints: `checkpoint.npz` (every array of the pool, active mask and free slots included, of
the optimizer state, of the strategy state and of the views' own parameters, plus the step)
and `checkpoint.json` (step, pair capacities, pool size, skipped steps, the run's configuration
and its data), each written whole (`lgs_jax.files.written`). Resuming restores those bits
exactly: with the same configuration, a resumed run continues bit-identically to an
uninterrupted one (views and random keys depend only on the step and the seed). A checkpoint
that cannot be read, or does not fit the run, raises `CheckpointError` naming the file and the
problem before anything in the folder changes.
"""

from __future__ import annotations

import dataclasses
import json
import os
import zipfile
import zlib

import jax
import jax.numpy as jnp
import numpy as np

from ..files import written

PARTS = ("pool", "opt", "strategy", "views")  # views: `view_params`' state, None without it
META = dict(step=0, capacity=1, eval_capacity=1, pool_size=1, skipped=0)  # int fields, minimum


class CheckpointError(ValueError):
    """A checkpoint file that cannot be resumed from: the file and the problem."""

    def __init__(self, path: str, problem: str):
        super().__init__(f"{path}: {problem}; fix or remove it, or start a new run (--overwrite)")
        self.path = path


def config_of(config) -> dict:
    """What a resumed run must share with the saved one: the recipe, train_on_all, the strategy
    and the seed (not the run length, the backend, the evaluation and checkpoint periods, the
    buffers' headrooms, the images' streaming, the start: none changes a resumed run's
    result)."""
    settings = dict(dataclasses.asdict(config.recipe), train_on_all=config.train_on_all)
    return dict(strategy=type(config.strategy).__name__,
                strategy_settings=dataclasses.asdict(config.strategy), settings=settings,
                seed=config.seed)


def default_config(config) -> dict:
    """`config_of` the default recipe and strategy (of config's strategy type): what a field
    that a checkpoint predates counts as (`config_mismatch`). On one device: the default
    recipe's batch need not split over config's devices."""
    from .config import Recipe

    return config_of(dataclasses.replace(config, recipe=Recipe(),
                                         strategy=type(config.strategy)(), devices=1,
                                         gaussian_devices=1))


def data_of(config, data_path: str) -> dict:
    """The data a run trains on, as recorded: the dataset folder (real path), downscale, crop
    and the images' type."""
    return dict(path=os.path.realpath(data_path), downscale=config.downscale,
                crop=None if config.crop is None else list(config.crop),
                uint8_images=config.uint8_images)


def describe(data: dict) -> str:
    """`data_of`'s record in words."""
    text = f"{data.get('path')} at downscale {data.get('downscale')}"
    if data.get("crop"):
        text += f", crop {' '.join(map(str, data['crop']))}"
    return text + (", 8-bit images" if data.get("uint8_images") else "")


def save(out: str, state: tuple, meta: dict) -> None:
    """Write (pool, opt_state, strategy_state, views) and `meta` (json-able, with its step) as
    the checkpoint."""
    arrays = {f"{name}_{i}": np.asarray(x) for name, part in zip(PARTS, state)
              for i, x in enumerate(jax.tree.leaves(part))}
    with written(os.path.join(out, "checkpoint.npz")) as tmp:
        np.savez(tmp, step=np.int64(meta["step"]), **arrays)
    with written(os.path.join(out, "checkpoint.json")) as tmp, open(tmp, "w") as f:
        json.dump(meta, f, indent=1)


def read_meta(out: str) -> dict:
    """checkpoint.json, checked (`CheckpointError`), beside a zip file of arrays; ValueError for
    a checkpoint of an older lgs_jax.train."""
    path = os.path.join(out, "checkpoint.json")
    try:
        with open(path) as f:
            meta = json.load(f)
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CheckpointError(path, f"not JSON ({e})") from None
    if not isinstance(meta, dict):
        raise CheckpointError(path, f"expected a JSON object, got {type(meta).__name__}")
    arrays = os.path.join(out, "checkpoint.npz")
    if "config" not in meta:
        raise ValueError(f"resume: {out} holds a checkpoint of an older lgs_jax.train (no "
                         "configuration in checkpoint.json); start a new run (--overwrite)")
    for key, low in META.items():
        v = meta.get(key)
        if not isinstance(v, int) or isinstance(v, bool) or v < low:
            raise CheckpointError(path, f"{key}: expected an int >= {low}, got {v!r}")
    if meta.get("rows") is not None and not (isinstance(meta["rows"], int) and meta["rows"] > 0):
        raise CheckpointError(path, f"rows: expected null or an int >= 1, got {meta['rows']!r}")
    if not isinstance(meta["config"], dict) or not isinstance(meta.get("data", {}), dict):
        raise CheckpointError(path, "config and data: expected JSON objects")
    if not os.path.exists(arrays):
        raise CheckpointError(arrays, "missing (checkpoint.json names a checkpoint it lacks)")
    try:
        with zipfile.ZipFile(arrays):  # its directory (at the end: a truncated file has none);
            pass  # the members' bytes are checked as `restore` reads them
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as e:
        raise CheckpointError(arrays, f"not a readable .npz file ({e or type(e).__name__})") \
            from None
    return meta


def restore(out: str, templates: tuple, step: int) -> tuple:
    """(pool, opt_state, strategy_state, views) from the checkpoint of `step`, shaped like
    `templates` (the same structures at the saved pool size); `CheckpointError` for arrays
    missing, of other shapes or types, or of another step."""
    path = os.path.join(out, "checkpoint.npz")
    try:
        with np.load(path) as saved:
            arrays = {k: saved[k] for k in saved.files}
    except (zipfile.BadZipFile, EOFError, OSError, zlib.error, ValueError) as e:
        raise CheckpointError(path, f"not a readable .npz file ({e or type(e).__name__})") \
            from None
    if "step" in arrays and int(arrays["step"]) != step:  # written before the step's .json
        raise CheckpointError(path, f"of step {int(arrays['step'])}, but checkpoint.json is "
                                    f"of step {step}")
    parts = []
    for name, template in zip(PARTS, templates):
        leaves, treedef = jax.tree.flatten(template)
        have = {k for k in arrays if k.startswith(f"{name}_")}
        want = {f"{name}_{i}" for i in range(len(leaves))}
        if have != want:
            missing = sorted(want - have, key=len)[:1] or ["none"]
            raise CheckpointError(path, f"holds {len(have)} arrays of the {name} state, this "
                                        f"run's configuration has {len(leaves)} (missing: "
                                        f"{missing[0]})")
        got = []
        for i, leaf in enumerate(leaves):
            a = arrays[f"{name}_{i}"]
            dtype = getattr(leaf, "dtype", a.dtype)
            if a.shape != np.shape(leaf) or a.dtype != dtype:
                raise CheckpointError(path, f"{name}_{i} is {a.dtype}{list(a.shape)}, this run's "
                                            f"is {dtype}{list(np.shape(leaf))}")
            got.append(jnp.asarray(a))
        parts.append(jax.tree.unflatten(treedef, got))
    return tuple(parts)


def config_mismatch(saved: dict, current: dict, defaults: dict | None = None) -> str | None:
    """A sentence naming what differs between a checkpoint's configuration and this run's, or
    None. Keys the saved configuration lacks (written before they were recorded) are not
    compared; within the settings and the strategy's, a field it lacks counts as its value in
    `defaults` (`default_config`)."""
    diff = []
    for k, v in current.items():
        if k not in saved:
            continue
        if isinstance(v, dict) and isinstance(saved[k], dict):
            was = {**(defaults or {}).get(k, {}), **saved[k]}
            diff += [f"{k}.{f}: {was.get(f)!r} -> {x!r}" for f, x in v.items()
                     if was.get(f) != x]
        elif saved[k] != v:
            diff.append(f"{k}: {saved[k]!r} -> {v!r}")
    if not diff:
        return None
    return "the checkpoint was made with other settings (" + "; ".join(diff) + ")"
