"""Configuration fields that document and check themselves: `option` declares a dataclass
field with its help text and bounds (what the `fit` command line is generated from,
`lgs_jax.cli.options`), `check` validates an instance against its fields' types and bounds.

Types `check` knows: bool, int, float (finite), str, `Literal[...]`, `X | None`, fixed-length
`tuple[int, ...]`, and dataclasses and classes (an instance of it); others are not checked.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from typing import Any, Literal

import numpy as np


def option(default: Any = dataclasses.MISSING, help: str = "", *, low=None, high=None,
           choices: tuple | None = None, flag: str | None = None, metavar=None,
           exclusive: str | None = None) -> Any:
    """A dataclass field with `default` and its metadata: help (one or a few sentences, the
    command line's help), low / high (inclusive bounds of a number), choices (the values a
    str may take, where the type is not a Literal), flag (the command-line option, default
    --field-name), metavar, exclusive (a name shared by options that exclude each other)."""
    meta = dict(help=help, low=low, high=high, choices=choices, flag=flag, metavar=metavar,
                exclusive=exclusive)
    return dataclasses.field(default=default, metadata=meta)


@functools.cache
def hints(cls) -> dict:
    """The resolved type of each field of dataclass `cls`."""
    return typing.get_type_hints(cls)


def split_optional(t) -> tuple[Any, bool]:
    """(X, True) for `X | None` (or Optional[X]), else (t, False)."""
    if typing.get_origin(t) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(t) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(t)) == 2:
            return args[0], True
    return t, False


def _number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def problem(t, v, meta: dict) -> str | None:
    """What is wrong with value `v` for type `t` and a field's metadata, or None."""
    t, optional = split_optional(t)
    if v is None and optional:
        return None
    low, high, choices = meta.get("low"), meta.get("high"), meta.get("choices")
    origin = typing.get_origin(t)
    if t is bool:
        return None if isinstance(v, (bool, np.bool_)) else f"expected a bool, got {v!r}"
    if t in (int, float):
        integral = t is int
        if not _number(v) or (integral and not isinstance(v, (int, np.integer))):
            return f"expected {'an int' if integral else 'a number'}, got {v!r}"
        if not math.isfinite(v):
            return f"expected a finite number, got {v!r}"
        if (low is not None and v < low) or (high is not None and v > high):
            bounds = (f"from {low} to {high}" if low is not None and high is not None
                      else f">= {low}" if low is not None else f"<= {high}")
            return f"expected {'an int' if integral else 'a number'} {bounds}, got {v!r}"
        return None
    if origin is Literal or choices is not None:
        known = typing.get_args(t) if origin is Literal else choices
        return None if v in known else f"expected one of {known}, got {v!r}"
    if t is str:
        return None if isinstance(v, str) else f"expected a str, got {v!r}"
    if origin is tuple:
        args = typing.get_args(t)
        if not isinstance(v, tuple) or len(v) != len(args):
            return f"expected a tuple of {len(args)} values, got {v!r}"
        for x, a in zip(v, args):
            wrong = problem(a, x, meta)
            if wrong:
                return f"{wrong} in {v!r}"
        return None
    if isinstance(t, type) and not isinstance(v, t):
        return f"expected a {t.__name__}, got {type(v).__name__}"
    return None


def check(obj, prefix: str = "") -> None:
    """Raise `ValueError` naming the field (`prefix` + name) of dataclass instance `obj`
    whose value does not fit its type and bounds."""
    for f in dataclasses.fields(obj):
        wrong = problem(hints(type(obj))[f.name], getattr(obj, f.name), f.metadata)
        if wrong:
            raise ValueError(f"{prefix}{f.name}: {wrong}")
