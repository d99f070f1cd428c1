"""The training recipes by name (`Recipe.name`): the values that `Recipe` and `FitConfig` fields
left None take, and the strategies the command line names (`STRATEGIES`).

  default  gsplat simple_trainer's recipe: 30,000 steps of one view, full resolution
           throughout, `DefaultStrategy` (3DGS's clone, split and prune), no early stop.
  fast     a recipe for time to quality, from published techniques, each a field to ablate:
           2,000 steps of 2 views (`Recipe.batch`: 4,000 view passes, against the 7,000 of
           gsplat's 7k result); images coarse to fine (`Recipe.levels`, DashGaussian: 1/4,
           1/2, then full resolution from half the run, `Recipe.full_resolution_at`);
           `budget.BudgetStrategy` (MCMC with its count on Taming 3DGS's budget curve, reached
           at step 1,000 where the images reach full resolution, and Gaussians no view sees
           relocated, after Speedy-Splat); SH bands every 500 steps (`Recipe.sh_every`: degree
           3 at step 1,500); an early stop when the training loss stops falling
           (`Recipe.early_stop`, `early_stop`). Measured against gsplat's 7,000-step result by
           benchmarks/time_to_quality.py. On a wide random start (`WIDE_START_VALUES`: a
           real capture without SfM points, whose start is random points in gsplat's cube of
           3 x the scene scale): 4,000 steps with `DefaultStrategy` instead, since MCMC's
           relocation of points spread so wide needs more steps than the budget schedule has
           (measured on fox: docs/design-notes.md). A NeRF-synthetic object's start, in a
           cube around the object, keeps the budget.

A field given explicitly keeps its value under either recipe and either start. The values are
filled in when the `Recipe` or `FitConfig` is made (the wide start's by `fit`, once it knows the
capture), so `dataclasses.replace(config, recipe=Recipe(name="fast"))` keeps the run's already
filled steps and strategy: make a new `FitConfig` instead.
"""

from __future__ import annotations

import dataclasses

from .budget import BudgetStrategy
from .strategy import DefaultStrategy, MCMCStrategy, Strategy

NAMES = ("default", "fast")
RECIPE_VALUES = {  # Recipe fields
    "default": dict(batch=1, levels=1, early_stop=False, sh_every=1000),
    "fast": dict(batch=2, levels=3, early_stop=True, sh_every=500),
}
RUN_VALUES = {  # FitConfig fields (and the strategy, by its command-line name)
    "default": dict(steps=30_000, strategy="default"),
    "fast": dict(steps=2_000, strategy="budget"),
}
WIDE_START_VALUES = {  # FitConfig fields for a wide random start (`for_start`)
    "default": {},
    "fast": dict(steps=4_000, strategy="default"),
}
STRATEGIES = {"default": DefaultStrategy, "mcmc": MCMCStrategy, "budget": BudgetStrategy}
"""The strategies by their command-line names (`--strategy`)."""


def said(field: str) -> str:
    """The recipes' values of `field` in words, for help texts: "default 1, fast 2"."""
    table = RECIPE_VALUES if field in RECIPE_VALUES["default"] else RUN_VALUES
    return ", ".join(f"{name} {table[name][field]}" for name in NAMES)


def strategy_of(name: str, max_gaussians: int, values: dict | None = None) -> Strategy:
    """Recipe `name`'s strategy (the one `values`, default `RUN_VALUES[name]`, names) with its
    defaults (cap_max, where it has one, max_gaussians: as the command line sets it)."""
    cls = STRATEGIES[(values or RUN_VALUES[name])["strategy"]]
    if "cap_max" in {f.name for f in dataclasses.fields(cls)}:
        return cls(cap_max=max_gaussians)
    return cls()


def fill(obj, name: str) -> None:
    """Set the fields of `obj` (a frozen `Recipe` or `FitConfig`, in its __post_init__) that
    are None and that recipe `name` gives a value to. A `FitConfig` records the fields it
    filled (`filled`), which `for_start` may set again."""
    is_run = hasattr(obj, "recipe")
    if is_run:
        values = dict(RUN_VALUES[name], strategy=strategy_of(name, obj.max_gaussians))
    else:
        values = RECIPE_VALUES[name]
    left = [field for field in values if getattr(obj, field) is None]
    for field in left:
        object.__setattr__(obj, field, values[field])
    if is_run:
        object.__setattr__(obj, "_filled", frozenset(left))


def filled(config) -> frozenset:
    """The fields of `config` (a `FitConfig`) that its recipe filled in (`fill`): left None
    when it was made. `dataclasses.replace` makes a configuration whose fields all count as
    given."""
    return getattr(config, "_filled", frozenset())


def for_start(config, wide, log=print):
    """`config` for its capture: itself, or where the start is wide (`wide()`: the capture
    has no SfM points and is no NeRF-synthetic object, `init.wide_start`; called only where
    the answer matters), a new `FitConfig` whose recipe-filled fields (`filled`) take
    `WIDE_START_VALUES` of its recipe (said through `log`); fields given explicitly keep
    their values."""
    values = {k: v for k, v in WIDE_START_VALUES[config.recipe.name].items()
              if k in filled(config)}
    if not values or not wide():
        return config
    log(f"no SfM points: the {config.recipe.name} recipe's wide random start, "
        + ", ".join(f"{k} {v}" for k, v in values.items()))
    if "strategy" in values:
        values["strategy"] = strategy_of(config.recipe.name, config.max_gaussians, values)
    return dataclasses.replace(config, **values)
