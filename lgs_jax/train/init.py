"""Initial Gaussians, as gsplat's simple_trainer makes them (`create_splats_with_optimizers`).

Centres: the dataset's SfM points with their colours where it has them; otherwise `count`
points uniform in the cube [−e, e]³ around the origin, e = extent · scene_scale, with uniform
random colours (gsplat: `init_type="random"`, `init_extent` 3; 3DGS fills a ±1.3 cube for
NeRF-synthetic scenes: 0.25 x Lego's scene scale of 5.2). Then
  scales     log(init_scale · sqrt(mean of the squared distances to the 3 nearest neighbours))
             on all three axes;
  quats      uniform in [0, 1)⁴ (not normalised; normalised on use);
  opacities  logit(init_opacity);
  SH         band 0 = (rgb − 0.5) / C0, higher bands 0 (degree 3: 16 bases).
Deterministic given the seed (numpy's generator; gsplat uses torch's, so draws differ).
`start_gaussians` is what `fit` starts from (benchmarks/train_vs_gsplat.py gives gsplat the same).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..io.datasets import dataset_info
from ..scene import Gaussians
from ..sh import C0


def knn_scale(points: np.ndarray) -> np.ndarray:
    """(N,) sqrt of the mean squared distance of each point to its 3 nearest other points."""
    k = min(4, len(points))
    d, _ = cKDTree(points).query(points, k=k)
    d = np.asarray(d).reshape(len(points), k)[:, 1:]
    if d.shape[1] == 0:
        return np.ones(len(points))
    return np.sqrt(np.mean(d * d, axis=1))


def random_points(count: int, half_width: float, seed: int):
    """(points, colors): `count` points uniform in [−half_width, half_width]³, colours in [0, 1)."""
    rng = np.random.default_rng([seed, 1])
    return (half_width * (rng.uniform(size=(count, 3)) * 2 - 1), rng.uniform(size=(count, 3)))


def initial_gaussians(points: np.ndarray, colors: np.ndarray, init_opacity: float,
                      init_scale: float, seed: int, sh_bases: int = 16,
                      dtype=np.float32) -> Gaussians:
    """Gaussians of `dtype` (float32 or float64: computed in float64, then rounded) at `points`
    with `colors` (module docstring); neighbour distances are floored at 1e-7 (coincident points
    would otherwise give log 0)."""
    points = np.asarray(points, np.float64)
    n = len(points)
    if n == 0:
        raise ValueError("points: no points to start from")
    scale = np.maximum(knn_scale(points), 1e-7) * init_scale
    rng = np.random.default_rng([seed, 2])
    sh = np.zeros((n, sh_bases, 3))
    sh[:, 0] = (np.asarray(colors, np.float64) - 0.5) / C0
    cast = lambda x: np.asarray(x, dtype)
    return Gaussians(cast(points), cast(rng.uniform(size=(n, 4))),
                     cast(np.repeat(np.log(scale)[:, None], 3, 1)),
                     cast(np.full(n, np.log(init_opacity / (1 - init_opacity)))), cast(sh))


def wide_start(data) -> bool:
    """Whether the capture `data` (a `Dataset` or its path; `io.datasets.dataset_info`) starts
    wide: no SfM points, and no NeRF-synthetic object (whose random points fill a cube of 0.25,
    not 3, times the scene scale by default: `start_gaussians`). Decided by the capture alone,
    whatever a run's init_extent."""
    info = dataset_info(data)
    return info.sfm_points == 0 and not info.nerf_synthetic


def start_gaussians(rd, config, log=print) -> Gaussians:
    """The initial Gaussians of a run (`config`: a `FitConfig`) on `rd` (a `feed.RunData`): its
    SfM points (a random subset of config.max_gaussians if it has more) or
    `config.start_points` random ones (at most max_gaussians; by default one per
    `config.PIXELS_PER_POINT` pixels of the largest training image, so a small image starts
    with few points) in the cube of half-width init_extent · scene_scale (init_extent None:
    0.25 for NeRF-synthetic scenes, 3 otherwise), with the strategy's initial opacity and
    scale, drawn from config.seed, in config.precision."""
    points, colors = rd.points, rd.colors
    cap, seed, strategy = config.max_gaussians, config.seed, config.strategy
    if len(points) == 0:
        extent = config.init_extent
        extent = extent if extent is not None else (0.25 if rd.nerf_synthetic else 3.0)
        n = min(config.start_points(max(w * h for w, h in rd.sizes)), cap)
        log(f"no SfM points: {n} random points in a cube of half-width {extent:g} x scene scale")
        points, colors = random_points(n, extent * rd.scene_scale, seed)
    elif len(points) > cap:
        keep = np.sort(np.random.default_rng([seed, 3]).choice(len(points), cap, False))
        log(f"{len(points)} SfM points, more than the cap: a random {cap} of them")
        points, colors = points[keep], colors[keep]
    return initial_gaussians(points, colors, strategy.init_opacity, strategy.init_scale, seed,
                             (config.recipe.sh_degree + 1) ** 2, np.dtype(config.precision))
