"""The `python -m lgs_jax` command line: `main` dispatches to the subcommands (render, info, fit,
video, view, eval); `args` holds the pieces they share."""

from .commands import ahead_mode, main, parser, use_compile_cache

__all__ = ["ahead_mode", "main", "parser", "use_compile_cache"]
