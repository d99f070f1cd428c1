"""Tiny captures for the dataset and camera tests: a transforms.json or COLMAP model with a few
small images, written into a folder."""

import json
import os

import numpy as np
from PIL import Image

from tests.io import colmap_format as cf


def write_frames(root, meta, frames, size=(40, 30), alpha=False):
    os.makedirs(os.path.join(root, "images"), exist_ok=True)
    for fr in frames:
        mode = "RGBA" if alpha else "RGB"
        Image.new(mode, size, (10, 20, 30, 0) if alpha else (10, 20, 30)).save(
            os.path.join(root, fr["file_path"]))
    path = os.path.join(root, "transforms.json")
    with open(path, "w") as f:
        json.dump(dict(meta, frames=frames), f)
    return path


def tiny_colmap(root, model=(1, (8.0, 8.0, 4.0, 3.0)), images=("a.png", "b.png"), camera_id=1,
                poses=None, point=(0.0, 0.0, 0.0), fmt="bin"):
    """A COLMAP model of one 8x6 camera (`model`: model id, params) and black 8x6 images;
    `poses` maps an image name to its (qvec, tvec) (default: identity rotation, t = (0, 0, 1));
    one SfM point at `point`; `fmt` "bin" or "txt"."""
    os.makedirs(os.path.join(root, "images"), exist_ok=True)
    for name in images:
        Image.new("RGB", (8, 6)).save(os.path.join(root, "images", name))
    poses = poses or {}
    ims = [(i + 1, *poses.get(n, ((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0))), camera_id, n, [])
           for i, n in enumerate(images)]
    write = cf.write_bin if fmt == "bin" else cf.write_txt
    write(os.path.join(root, "sparse", "0"), [(1, model[0], 8, 6, model[1])], ims,
          [(1, point, (1, 2, 3), 0.5, [])])


def tiny_transforms(root, **meta):
    """A transforms.json with one 40x30 frame, images/a.png; `meta` adds to (or, as None, removes
    from) the shared fields, fl_x=40 by default."""
    meta = {k: v for k, v in dict(dict(fl_x=40.0), **meta).items() if v is not None}
    frames = [dict(file_path="images/a.png", transform_matrix=np.eye(4).tolist())]
    return write_frames(root, meta, frames)
