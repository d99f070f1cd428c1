"""The `python -m lgs_jax` command line: `main` dispatches to the subcommands (render, info, fit,
video, view, eval; `fit` is generated from `lgs_jax.train.FitConfig` by `options`); `args` holds
the pieces they share."""

from .commands import main, parser, use_compile_cache

__all__ = ["main", "parser", "use_compile_cache"]
