"""Tiny captures written on the fly for the run tests (a NeRF-synthetic layout: view 0 held
out), and a run folder holding a checkpoint without a training step compiled."""

import json
import os

import numpy as np


def tiny_capture(folder, views: int = 4, size: int = 16, seed: int = 0) -> str:
    """`views` random size x size RGB photos around the origin with a transforms_train.json;
    returns the folder."""
    import matplotlib.image

    (folder / "train").mkdir(parents=True)
    rng = np.random.default_rng(seed)
    frames = []
    for i in range(views):
        matplotlib.image.imsave(folder / "train" / f"r_{i}.png", rng.uniform(size=(size, size, 3)))
        pose = np.eye(4)
        pose[:3, 3] = [0.1 * i, 0.0, 3.0]  # Blender axes: the camera looks down -z at 0
        frames.append(dict(file_path=f"./train/r_{i}", transform_matrix=pose.tolist()))
    (folder / "transforms_train.json").write_text(json.dumps(dict(camera_angle_x=0.7,
                                                                  frames=frames)))
    return str(folder)


def run_folder(config, step: int) -> None:
    """config.out holding the checkpoint of a run of `config` at `step` (its start's state,
    saved as if `step` steps were done), as `fit` writes it."""
    from lgs_jax import train
    from lgs_jax.train import checkpoint, feed, state

    rd = feed.prepare(config.data)
    setup = train.Setup.of(config, rd.scene_scale, "reference")
    st = state.fresh(config, setup, rd, lambda m: None)
    st.step = step
    os.makedirs(config.out, exist_ok=True)
    state.save(config.out, config, st, checkpoint.data_of(config, config.data))
    with open(f"{config.out}/metrics.jsonl", "w") as f:
        f.writelines(json.dumps(dict(step=s + 1, loss=0.5)) + "\n" for s in range(step))
