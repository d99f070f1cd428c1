"""The live values at the peak of an XLA GPU buffer assignment dump (offline analysis).

    python scripts/hlo_peak.py DIR/module_*.jit_loss.*after_optimizations  [--top 40]

Reads the dump's -buffer-assignment.txt (values, their allocations and byte ranges) and
-live-range.txt (each value's live range in the schedule), sums the bytes live at each step
(per allocation, the union of live values' byte ranges; parameters left out, as XLA's
temp + output sizes do) and prints the peak's step, instruction and live values by size.
`--temp` leaves the outputs' allocations out too (what XLA can pack into its temporary
allocation), `--timeline` prints the live MiB at every step, `--step N` the values live at
step N instead of the peak's.
"""

import argparse
import collections
import re


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("prefix")
    ap.add_argument("--top", type=int, default=40)
    ap.add_argument("--timeline", action="store_true", help="the live MiB at every step")
    ap.add_argument("--step", type=int, help="the live values at this step, not at the peak")
    ap.add_argument("--temp", action="store_true",
                    help="the temporary allocation only (outputs' allocations left out: XLA's "
                         "memory analysis adds their whole size)")
    a = ap.parse_args()
    values, params = {}, set()
    alloc = None
    for line in open(a.prefix + "-buffer-assignment.txt"):
        m = re.match(r"allocation (\d+): size (\d+)(.*)", line)
        if m:
            alloc = int(m.group(1))
            if ("parameter" in m.group(3) or "constant" in m.group(3)
                    or (a.temp and "maybe-live-out" in m.group(3))):
                params.add(alloc)
            continue
        m = re.match(r" value: <\d+ (\S+) @\d+> \(size=(\d+),offset=(\d+)\): (.*)", line)
        if m and alloc is not None:
            name = m.group(1) if m.group(1).endswith("}") else m.group(1) + "{}"
            values[name] = (alloc, int(m.group(3)), int(m.group(2)), m.group(4))
        if line.startswith("Used values") or line.startswith("HloLiveRange"):
            break
    text = open(a.prefix + "-live-range.txt").read()
    seq = dict(re.findall(r"^\s+(\d+):(\S+)$", text.split("BufferLiveRange")[0], re.M))
    ranges = {}
    for name, lo, hi in re.findall(r"^\s+(\S+):(\d+)-(\d+)$", text.split("BufferLiveRange")[1],
                                   re.M):
        ranges[name] = (int(lo), int(hi))
    end = max(hi for _, hi in ranges.values())
    best = (0, 0, [])
    for t in range(end + 1):
        per = collections.defaultdict(list)
        live = []
        for name, (lo, hi) in ranges.items():
            if lo <= t <= hi and name in values and values[name][0] not in params:
                al, off, size, shape = values[name]
                per[al].append((off, off + size))
                live.append((size, name, shape, al))
        total = 0
        for iv in per.values():
            iv.sort()
            cur = None
            for s, e in iv:
                if cur is None or s > cur[1]:
                    if cur:
                        total += cur[1] - cur[0]
                    cur = [s, e]
                else:
                    cur[1] = max(cur[1], e)
            if cur:
                total += cur[1] - cur[0]
        if a.timeline:
            print(f"{t:4d} {total / 2**20:8.1f} MiB  {seq.get(str(t))}")
        if total > best[0] or t == a.step:
            best = (total, t, live)
        if t == a.step:
            break
    total, t, live = best
    print(f"{'live' if a.step is not None else 'peak'} {total / 2**20:.1f} MiB at step {t}: "
          f"{seq.get(str(t))}")
    for size, name, shape, al in sorted(live, reverse=True)[:a.top]:
        lo, hi = ranges[name]
        print(f"{size / 2**20:9.2f} MiB  alloc {al:3d}  {lo:4d}-{hi:<4d} {name:55s} {shape}")


if __name__ == "__main__":
    main()
