"""Result rows in CSV files that several device calls fill: read, merged by key, numbers out.

A harness writes its rows as each run ends (`merge`), so a call cut short by its time limit
keeps what finished, and a rerun replaces its own rows (those of the same key)."""

from __future__ import annotations

import csv
import os


def read_csv(path: str) -> list[dict]:
    """The rows of the CSV at `path` (none where it does not exist), values as strings."""
    if not os.path.exists(path):
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def merge(path: str, rows: list[dict], fields: tuple, key: tuple) -> None:
    """Write `rows` into the CSV at `path`, replacing the rows there of the same `key` (compared
    as strings), whole: a temporary file renamed over it."""
    mine = {tuple(str(r.get(k)) for k in key) for r in rows}
    kept = [r for r in read_csv(path) if tuple(str(r.get(k)) for k in key) not in mine]
    tmp = path + ".tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(kept + rows)
    os.replace(tmp, path)


def number(v) -> float | None:
    """A cell as a float; None for an empty or non-numeric cell."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return None
