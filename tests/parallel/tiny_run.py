"""The tiny synthetic run of the Gaussian-parallel training tests (tests/parallel/
training_child.py, multihost_fit_child.py): its capture (`capture`) and configuration
(`config`). Importing it starts no JAX backend, so a child process may set its devices (XLA_FLAGS)
and collectives first."""

import numpy as np

import lgs_jax
from lgs_jax import train
from lgs_jax.io.datasets import Dataset

W, H = 32, 64  # 2 x 4 tiles: a band of one tile row per device on 4 devices
VIEWS = 5  # view 0 held out
POINTS = 301  # blocks of 151 + 150 on 2 devices, 76 + 3 x 75 on 4: uneven shards
POOL = 1024  # slots; no growth in the runs
STEPS, HALF = 8, 4
# refinements at steps 3 and 6, clones only (no split: grow_scale3d beyond any Gaussian), and
# prunes, never short of slots (a refinement at the cap ranks its candidates by their
# gradients): the parameters' differences across device counts stay within
# `sharded.drift_bound`
STRATEGY = train.DefaultStrategy(refine_start_iter=2, refine_every=3, grow_grad2d=3e-4,
                                 prune_opa=0.02, grow_scale3d=100.0)
# SH degree 0: within the runs' steps the higher bands are masked anyway (`Recipe.sh_every`),
# and their evaluation costs each step's compile a third more; the fast part's two views per
# step split over the 2 rows of its 2 x 2 mesh
RECIPE = train.Recipe(batch=1, sh_degree=0)

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


def config(out: str, gaussians: int, **kwargs) -> train.FitConfig:
    """The runs' configuration with the Gaussians split over `gaussians` devices (kwargs: other
    fields)."""
    kwargs = dict(dict(pair_headroom=4.0, strategy=STRATEGY, recipe=RECIPE, eval_every=100),
                  **kwargs)
    return train.FitConfig(data=out, out=out, steps=STEPS, max_gaussians=POOL, pool_size=POOL,
                           backend="reference", gaussian_devices=gaussians,
                           checkpoint_every=100, **kwargs)
