"""The `python -m lgs_jax` command line: `main` dispatches to the subcommands (render, info, fit,
video, view, eval; `fit` is generated from `lgs_jax.train.FitConfig` by `options`); `args` holds
the pieces they share."""

from .commands import cache_into, main, parser, use_compile_cache

__all__ = ["cache_into", "main", "parser", "use_compile_cache"]
