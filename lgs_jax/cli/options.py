"""Command-line options generated from configuration dataclasses (`lgs_jax.train.options`): one
option per field, named --field-name (or the field's `flag`), typed, ranged and documented by
the field; `values` reads them back, `argv` writes a value's options.

Options by type: bool fields false by default are switches (--pose-opt); other bools (true, or
None: "decide for me") get --x / --no-x; int and float fields are checked against the field's
bounds; Literal and `choices` fields take one of their values; a fixed-length tuple takes that
many values; `X | None` defaults to None. A field holding a dataclass (`Recipe`) contributes its
own fields' options, under their own names.
"""

from __future__ import annotations

import argparse
import dataclasses
import typing
from typing import Literal

from ..train.options import hints, split_optional
from .args import number_at_least


@dataclasses.dataclass(frozen=True)
class Option:
    """A generated option: its flag, the field it sets (`path`: the field names from the
    outer dataclass down), the field and the dataclass that declares it."""

    flag: str
    path: tuple
    field: dataclasses.Field
    owner: type

    @property
    def type(self):
        return hints(self.owner)[self.field.name]

    @property
    def dest(self) -> str:
        return self.path[-1]


def flag_of(f: dataclasses.Field) -> str:
    return f.metadata.get("flag") or "--" + f.name.replace("_", "-")


def fields_of(cls, nested: tuple = (), skip: tuple = ()) -> list[Option]:
    """The options of dataclass `cls`: one per field, fields that hold a dataclass of a type in
    `nested` replaced by that dataclass's options; fields named in `skip` left out."""
    out = []
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        t = hints(cls)[f.name]
        if t in nested:
            out += [dataclasses.replace(o, path=(f.name,) + o.path) for o in fields_of(t, nested)]
        else:
            out.append(Option(flag_of(f), (f.name,), f, cls))
    return out


def _help(f: dataclasses.Field, default) -> str:
    text = f.metadata.get("help", "")
    if not (default is None or default is False or default is dataclasses.MISSING):
        shown = " ".join(map(str, default)) if isinstance(default, tuple) else f"{default:g}" \
            if isinstance(default, float) else default
        text += f" (default: {shown})"
    return text.replace("%", "%%")


def argument(t, f: dataclasses.Field, default) -> dict:
    """argparse keywords for a field of type `t` whose option defaults to `default`."""
    meta = f.metadata
    t, optional = split_optional(t)
    kw = dict(help=_help(f, default), default=default)
    if default is dataclasses.MISSING:
        del kw["default"]
        kw["required"] = True
    if t is bool:
        kw["action"] = "store_true" if default is False else argparse.BooleanOptionalAction
        return kw
    if meta.get("metavar") is not None:
        kw["metavar"] = meta["metavar"]
    if typing.get_origin(t) is tuple:
        args = typing.get_args(t)
        t, kw["nargs"] = args[0], len(args)
    if t in (int, float):
        low = meta.get("low")
        kw["type"] = number_at_least(-float("inf") if low is None else low, t, meta.get("high"))
    elif typing.get_origin(t) is Literal:
        kw["choices"] = typing.get_args(t)
    elif meta.get("choices") is not None:
        kw["choices"] = meta["choices"]
    return kw


def add(parser, options: list[Option], defaults: dict | None = None) -> dict:
    """Add `options` to `parser` (defaults: flag -> the option's default where it is not the
    field's); options sharing a field's `exclusive` name go in one mutually exclusive group.
    Returns the groups by name."""
    groups = {}
    for o in options:
        default = (defaults or {}).get(o.flag, o.field.default)
        kw = argument(o.type, o.field, default)
        name = o.field.metadata.get("exclusive")
        target = parser
        if name is not None:
            if name not in groups:
                groups[name] = parser.add_mutually_exclusive_group()
            target = groups[name]
        target.add_argument(o.flag, dest=o.dest, **kw)
    return groups


def values(args, options: list[Option]) -> dict:
    """{path: value} of `options` as parsed into `args` (several values as a tuple)."""
    pick = lambda v: tuple(v) if isinstance(v, list) else v
    return {o.path: pick(getattr(args, o.dest)) for o in options}


def argv(value, option: Option, default) -> list[str]:
    """The command-line words that set `option` to `value` (none where it is `default`)."""
    if value == default and default is not dataclasses.MISSING:
        return []
    t, _ = split_optional(option.type)
    if t is bool:
        if default is False:
            return [option.flag]
        return [option.flag if value else "--no-" + option.flag[2:]]
    if value is None:
        raise ValueError(f"{option.flag}: None cannot be given on the command line")
    words = list(value) if isinstance(value, tuple) else [value]
    return [option.flag] + [f"{w!r}" if isinstance(w, float) else str(w) for w in words]
