"""An early stop on the training views alone (`Recipe.early_stop`): a run ends when its training
loss stops falling. Held-out views never decide it.

With W = `Recipe.stop_window` steps and g = `Recipe.stop_gain`: after step s (s steps done) the
run stops when s is a check (s − F a positive multiple of W with s − F >= 2W, F the first step
at full resolution, `levels.starts`) and

    mean(loss of steps s − W + 1 .. s) > (1 − g) · mean(loss of steps s − 2W + 1 .. s − W),

the losses being the training steps' (`step.train_step`'s loss, as metrics.jsonl records it;
non-finite ones, of skipped steps, left out of the means). The rule reads only recorded losses,
so it decides the same in a run resumed from a checkpoint (the losses of steps up to the
checkpoint read back from metrics.jsonl) as in an uninterrupted run, and a run resumed at the
step it stopped at stops again before any step.
"""

from __future__ import annotations

import math


def is_check(step: int, first: int, window: int) -> bool:
    """Whether the rule is evaluated after `step` steps (module docstring; `first` = F)."""
    done = step - first
    return done >= 2 * window and done % window == 0


def _mean(losses: dict, lo: int, hi: int) -> float:
    """The mean of the finite losses of steps lo .. hi (1-based), NaN where there are none;
    `KeyError` for a step that has none recorded."""
    values = [losses[s] for s in range(lo, hi + 1)]
    finite = [v for v in values if math.isfinite(v)]
    return math.fsum(finite) / len(finite) if finite else math.nan


def plateaued(losses: dict, step: int, window: int, gain: float) -> bool:
    """Whether the mean loss of the last `window` steps before `step` (inclusive) fell less
    than `gain` (a fraction) below the window's before it; `losses`: step (1-based) -> loss.
    False where either mean is not finite."""
    recent = _mean(losses, step - window + 1, step)
    before = _mean(losses, step - 2 * window + 1, step - window)
    return recent > (1.0 - gain) * before


class EarlyStop:
    """The rule over a run's losses: `record(step, loss)` after each step, `due(step)` whether
    the run ends after `step` steps. Off (never due) unless `on`."""

    def __init__(self, on: bool, first: int, window: int, gain: float,
                 losses: dict | None = None, source: str = "metrics.jsonl"):
        self.on, self.first, self.window, self.gain = on, first, window, gain
        self.losses = dict(losses or {})
        self.source = source
        self._decided: dict[int, bool] = {}

    @classmethod
    def of(cls, recipe, first: int, rows: list[dict] = (), source: str = "metrics.jsonl",
           done: int = 0):
        """The rule of `recipe` for a run with `done` steps done, its losses so far from
        metrics rows (`report.read_metrics`; those of the training steps); `ValueError` naming
        `source` where a loss a later check needs is missing (a resumed run whose metrics lost
        rows), before any step."""
        losses = {r["step"]: r["loss"] for r in rows if "loss" in r and "step" in r}
        rule = cls(recipe.early_stop, first, recipe.stop_window, recipe.stop_gain, losses,
                   source)
        if rule.on:
            need = range(max(first, done - 2 * rule.window) + 1, done + 1)
            lost = [s for s in need if s not in losses]
            if lost:
                raise ValueError(f"{source}: no training loss of step {lost[0]}, which the "
                                 f"early stop needs (recipe.early_stop); restore the run's "
                                 f"metrics or start a new run")
        return rule

    def record(self, step: int, loss: float) -> None:
        """The loss of step `step` (1-based: `step` steps done)."""
        self.losses[step] = float(loss)

    def checks(self, step: int) -> bool:
        """Whether the rule decides after `step` steps (`due` may be true only then)."""
        return self.on and is_check(step, self.first, self.window)

    def due(self, step: int) -> bool:
        """Whether the run ends after `step` steps; `ValueError` naming `source` where a loss
        the rule needs was never recorded (a resumed run whose metrics lost rows)."""
        if not self.checks(step):
            return False
        if step not in self._decided:
            try:
                self._decided[step] = plateaued(self.losses, step, self.window, self.gain)
            except KeyError as e:
                raise ValueError(f"{self.source}: no training loss of step {e.args[0]}, which "
                                 f"the early stop after step {step} needs (recipe.early_stop)"
                                 ) from None
        return self._decided[step]

    def means(self, step: int) -> tuple[float, float]:
        """(mean over the window before, mean over the last window) at a check `step`."""
        w = self.window
        return (_mean(self.losses, step - 2 * w + 1, step - w),
                _mean(self.losses, step - w + 1, step))
