"""Which programs a command compiles, in which thread, from where, and for how long.

    python scripts/compile_events.py [--top N] [--least S] [--json FILE] fit --data DIR ...

Runs `python -m lgs_jax ARGS` in this process (the persistent cache as the command line sets
it: LGS_JAX_CACHE) with listeners on JAX's compile events (`train.report.COMPILE_EVENTS`: the
trace to a jaxpr, the lowering to MLIR, XLA's compile or the persistent cache's load) and on
the cache's hits, then prints:

  - per thread (the command's, and the others together: `fit`'s compiles ahead) and part: the
    events and their seconds (overlaps within the group counted once), and the cache hits;
  - the `--top` (program, part) pairs by seconds, each with its thread ("main" or "ahead"),
    count and longest;
  - every trace in the command's thread of at least `--least` seconds: its start (seconds from
    the command's start), length, program and call site (the nearest lgs_jax frames).

`fit` reports the same split for its loop (`compile_parts` in result.json); this says which
programs make it up. `--json FILE` writes every event.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import threading
import time
import traceback

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _site() -> str:
    """The nearest frames of lgs_jax's own code (the library's, not this script's), innermost
    first."""
    frames = [f for f in traceback.extract_stack()
              if f"{os.sep}lgs_jax{os.sep}" in f.filename and "site-packages" not in f.filename]
    return " < ".join(f"{os.path.basename(f.filename)}:{f.lineno}:{f.name}"
                      for f in frames[::-1][:4])


def record(argv: list[str]) -> tuple[int, list[dict], float]:
    """(exit code, events, start time) of `python -m lgs_jax argv` run here."""
    import jax

    from lgs_jax.cli.commands import main
    from lgs_jax.train.report import CACHE_HIT, COMPILE_EVENTS

    events, command = [], threading.get_ident()

    def span(event, start, end, **kw):
        part = COMPILE_EVENTS.get(event)
        if part is not None:
            events.append(dict(part=part, start=start, end=end, program=kw.get("fun_name"),
                               main=threading.get_ident() == command,
                               site=_site() if part == "trace" else None))

    def hit(event, **_):
        if event == CACHE_HIT:
            events.append(dict(part="cache hit", start=time.time(), end=time.time(),
                               program=None, main=threading.get_ident() == command, site=None))

    jax.monitoring.register_event_time_span_listener(span)
    jax.monitoring.register_event_listener(hit)
    t0 = time.time()
    try:
        code = main(argv)
    finally:
        jax.monitoring.unregister_event_time_span_listener(span)
        jax.monitoring.unregister_event_listener(hit)
    return code, events, t0


def _union(spans) -> float:
    total, reach = 0.0, float("-inf")
    for start, end in sorted(spans):
        if end > reach:
            total += end - max(start, reach)
            reach = end
    return total


def summary(events: list[dict], t0: float, top: int, least: float) -> str:
    lines = []
    for label, main in (("the command's thread", True), ("other threads", False)):
        mine = [e for e in events if e["main"] == main]
        parts = [f"{part} {len(ev)} events {_union([(e['start'], e['end']) for e in ev]):.2f} s"
                 for part in ("trace", "lower", "backend")
                 for ev in [[e for e in mine if e["part"] == part]]]
        hits = sum(e["part"] == "cache hit" for e in mine)
        every = _union([(e["start"], e["end"]) for e in mine])
        lines.append(f"{label}: {every:.2f} s compiling; " + ", ".join(parts)
                     + f"; {hits} cache hits")
    by = collections.defaultdict(list)
    for e in events:
        if e["part"] != "cache hit":
            by[("main" if e["main"] else "ahead", e["part"], e["program"])].append(
                e["end"] - e["start"])
    lines.append(f"\nthe {top} longest (thread, part, program):")
    for (thread, part, program), times in sorted(by.items(), key=lambda kv: -sum(kv[1]))[:top]:
        lines.append(f"  {thread:5s} {part:7s} {program[:48]:48s} {len(times):3d} x, "
                     f"{sum(times):7.2f} s, longest {max(times):6.2f} s")
    lines.append(f"\ntraces of {least} s or more in the command's thread (start s, seconds, "
                 "program, call site):")
    for e in events:
        if e["main"] and e["part"] == "trace" and e["end"] - e["start"] >= least:
            lines.append(f"  {e['start'] - t0:8.2f} {e['end'] - e['start']:6.3f} "
                         f"{e['program'][:32]:32s} {e['site']}")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--top", type=int, default=20, help="(program, part) pairs listed")
    parser.add_argument("--least", type=float, default=0.01,
                        help="the shortest trace listed, in seconds")
    parser.add_argument("--json", help="write every event to this file")
    parser.add_argument("command", nargs=argparse.REMAINDER,
                        help="the lgs_jax command line, e.g. fit --data DIR --out DIR")
    args = parser.parse_args()
    if not args.command:
        parser.error("give the lgs_jax command to run, e.g. fit --data DIR --out DIR")
    sys.path.insert(0, ROOT)
    code, events, t0 = record(args.command)
    print(summary(events, t0, args.top, args.least))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(start=t0, events=events), f)
    return code


if __name__ == "__main__":
    sys.exit(main())
