"""Coarse to fine (DashGaussian, Chen et al., CVPR 2025: low resolution early, full
resolution late), in a few static sizes: `Recipe.levels` = L levels, level l (0-based) trains
on the images downscaled by 2^(L − 1 − l), each level from a fixed step (`starts`), the last at
full resolution from `Recipe.full_resolution_at` of the run; the coarser levels share the steps
before it equally. Each image size compiles its own training step, so a few fixed levels stand
for DashGaussian's gradual schedule (docs/design-notes.md).

A level's images are made once, when the run starts, from the loaded training images: each k x
k block averaged (in float64, then float32; 8-bit images rounded to the nearest 8-bit value)
after dropping the last H % k rows and W % k columns, as `load_dataset(downscale=k)` does; its
cameras have every intrinsic divided by k exactly (pixel j covers the full-size pixels k·j ..
k·j + k − 1, whose centre k·(j + 0.5) is the full-size coordinate of j + 0.5) and the same
poses. Held-out views are always rendered and scored at full resolution. The views of a step
depend only on (step, seed) (`feed.views_for_step`), so a resumed run sees what an
uninterrupted one does, at the same level. The first steps scale with the run's length
(`FitConfig.steps`), as the means' learning rate does: a run resumed with more steps follows
the longer run's schedule from there.
"""

from __future__ import annotations

import bisect
import dataclasses

import jax
import numpy as np

from ..io.datasets import block_mean
from .feed import RunData, TrainViews


def factors(levels: int) -> tuple[int, ...]:
    """The downscale factor of each level, coarsest first: (2^(L − 1), ..., 2, 1)."""
    return tuple(2 ** (levels - 1 - level) for level in range(levels))


def starts(levels: int, steps: int, full_resolution_at: float) -> tuple[int, ...]:
    """The first (0-based) step of each level: level l of L starts at
    floor(l · full_resolution_at · steps / (L − 1)); the only level of one starts at 0."""
    if levels == 1:
        return (0,)
    full = full_resolution_at * steps
    return tuple(int(level * full / (levels - 1)) for level in range(levels))


def level_at(step: int, first_steps: tuple[int, ...]) -> int:
    """The level of 0-based `step`: the last whose first step (`starts`) is at or before it."""
    return bisect.bisect_right(first_steps, step) - 1


def downscaled(image: np.ndarray, k: int) -> np.ndarray:
    """(H, W, C) `image` averaged over k x k blocks (module docstring), in its dtype."""
    if k == 1:
        return image
    mean = block_mean(image, k)
    if image.dtype == np.uint8:
        return np.round(mean).astype(np.uint8)
    return mean.astype(np.float32)


def scaled_cameras(cams, k: int):
    """Stacked cameras (`feed.stack_any`) with every intrinsic divided by k and the stack's
    size floor-divided by it."""
    if k == 1:
        return cams
    return dataclasses.replace(cams, fx=cams.fx / k, fy=cams.fy / k, cx=cams.cx / k,
                               cy=cams.cy / k, width=cams.width // k, height=cams.height // k)


def check(train_sizes, levels: int) -> None:
    """Raise `ValueError` naming recipe.levels where the coarsest level would leave a training
    image (of `train_sizes`, (width, height) each) without a pixel."""
    k = factors(levels)[0]
    small = min(train_sizes, key=min)
    if min(small) < k:
        raise ValueError(f"recipe.levels: {levels} levels downscale the {small[0]}x{small[1]} "
                         f"training images by {k}, which leaves no pixel; use fewer levels")


@dataclasses.dataclass(frozen=True)
class Level:
    """One level's training data: its factor, cameras (stacked), images on the host (as
    `RunData.train_images`: an array, or a list where sizes differ) and sizes."""

    factor: int
    cams: object
    images: object
    sizes: tuple

    @classmethod
    def of(cls, rd: RunData, k: int) -> "Level":
        """Level of factor k of the run's training data."""
        if k == 1:
            return cls(1, rd.train_cams, rd.train_images, rd.train_sizes)
        images = [downscaled(im, k) for im in rd.train_images]
        if isinstance(rd.train_images, np.ndarray):
            images = np.stack(images)
        sizes = tuple((w // k, h // k) for w, h in rd.train_sizes)
        return cls(k, scaled_cameras(rd.train_cams, k), images, sizes)

    def camera(self, i: int = 0):
        """Training view i's camera at this level's size of its image."""
        width, height = self.sizes[i]
        return dataclasses.replace(jax.tree.map(lambda x: x[i], self.cams), width=width,
                                   height=height)

    def groups(self) -> np.ndarray | None:
        """Each view's index among the level's distinct sizes (`RunData.groups`)."""
        distinct = list(dict.fromkeys(self.sizes))
        return None if len(distinct) == 1 else np.array([distinct.index(s) for s in self.sizes])


class LevelFeed:
    """The training views of each step at the step's level: `args(step)` (targets, idx) and
    `cams(step)` (the stacked cameras at that level) are `step.train_step`'s arguments;
    `prefetch` and `close` as `feed.TrainViews`, one of which serves each level (its images on
    the device from the level's first step; those of the levels before it are released)."""

    def __init__(self, rd: RunData, batch: int, seed: int, stream: bool, levels: int = 1,
                 steps: int = 0, full_resolution_at: float = 0.5):
        self.batch, self.seed, self.stream = batch, seed, stream
        self.starts = starts(levels, steps, full_resolution_at)
        self.levels = [Level.of(rd, k) for k in factors(levels)]
        self._feeds: dict[int, TrainViews] = {}

    def level(self, step: int) -> int:
        """The level of 0-based `step` (`level_at`)."""
        return level_at(step, self.starts)

    def _feed(self, level: int) -> TrainViews:
        if level not in self._feeds:
            lv = self.levels[level]
            self._feeds[level] = TrainViews(lv.images, self.batch, self.seed, self.stream,
                                            lv.groups())
        return self._feeds[level]

    def args(self, step: int):
        """(targets, idx) of 0-based `step` (`TrainViews.args`) at its level."""
        level = self.level(step)
        for old in [lv for lv in self._feeds if lv < level]:
            self._feeds.pop(old).close()
        return self._feed(level).args(step)

    def prefetch(self, step: int) -> None:
        self._feed(self.level(step)).prefetch(step)

    def cams(self, step: int):
        """The training cameras (stacked) at `step`'s level."""
        return self.levels[self.level(step)].cams

    def close(self) -> None:
        for f in self._feeds.values():
            f.close()

    def describe(self) -> str:
        """The schedule in words (the first training view's size at each level)."""
        parts = [f"{'full resolution' if lv.factor == 1 else f'1/{lv.factor}'} "
                 f"({lv.sizes[0][0]}x{lv.sizes[0][1]}) from step {start}"
                 for lv, start in zip(self.levels, self.starts)]
        return "coarse to fine: " + ", ".join(parts)
