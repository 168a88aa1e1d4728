"""Wall time of the paper's whole grid on this machine, from measured per-point times.

The grid (issue 13): alpha 25, 50, 100, 200, 300 x a/g 0.079, 7.9, 790 at g = 0.5 m/s^2
(floor at 1, 10, 100 Hz, 1 mm), plus g = 10 at a/g 1 and 2.5 (15.9 and 25.2 Hz), 3 seeds,
5 s + 5 s. Every point's cost is the median ``wall_s`` of the matching rows (same alpha and
gravity, frequency within 2%, no static load) of the given ``rodwarp sweep`` results; the
newest source that has a point wins, so list older sweeps first; a single run's summary.json
counts as a source of one row. A point no source has is
listed as missing and left out, so the total is then a lower bound, and says so.

The wall time of ``rodwarp sweep --workers W`` is the makespan of its runs on W workers,
longest first (each worker takes the next run when it is free): never below the longest
single run, which the sum over W hides when a few runs dominate.

Sweeps that share the entangling (the default since ``rodwarp sweep`` groups the points of
one packing, docs/protocol.md): a row whose ``entangled_from`` names a donor cost only its
test, and its donor (the group's lowest frequency) costs the whole protocol. The schedule then
follows the sweep's: groups largest alpha first, a group's donor before its other points,
which start only once the donor is done, each worker taking the first ready run when it is
free. ``--no-share`` estimates the grid with every run entangling on its own (the rows of
branched points then cannot be used: their costs lack the entangling).

    python scripts/grid_estimate.py OLD/results.csv NEW/results.csv --workers 2 \
        --out benchmarks/results/grid_estimate.md
"""

from __future__ import annotations

import argparse
import heapq
import math
import statistics
import sys
from pathlib import Path

ALPHAS = (25.0, 50.0, 100.0, 200.0, 300.0)
DRIVES = ((0.5, 1.0), (0.5, 10.0), (0.5, 100.0), (10.0, 15.92), (10.0, 25.2))  # (g m/s^2, f Hz)
SEEDS = 3


def point_costs(sources: list[Path], shared: bool = True) -> dict:
    """(alpha, g, f) -> (median wall s, runs, source, branched) over the grid, the last source
    winning; ``branched``: the rows' runs took their entangled packing from a donor (their
    wall is the test's alone). With ``shared`` false, branched rows are not used."""
    import csv

    import json

    costs = {}
    for src in sources:
        if src.suffix == ".json":  # one run's summary.json
            s = json.loads(src.read_text())
            rows = [{"alpha": s["alpha"], "gravity": s["gravity"], "freq": s["freq"],
                     "static_load": s.get("static_load", 0.0), "wall_s": s["wall_time_s"]}]
        else:
            with open(src, newline="") as fh:
                rows = list(csv.DictReader(fh))
        for a in ALPHAS:
            for g, f in DRIVES:
                match = [r for r in rows
                         if r.get("wall_s") and r.get("status", "ok") == "ok"
                         and float(r["alpha"]) == a and float(r["gravity"]) == g
                         and abs(float(r["freq"]) / f - 1.0) < 0.02 and float(r.get("static_load") or 0.0) == 0.0]
                if not shared:
                    match = [r for r in match if not r.get("entangled_from")]
                branched = {bool(r.get("entangled_from")) for r in match}
                if len(branched) > 1:  # a point measured both ways: keep its most common kind
                    keep = sum(bool(r.get("entangled_from")) for r in match) * 2 >= len(match)
                    match = [r for r in match if bool(r.get("entangled_from")) == keep]
                if match:
                    costs[(a, g, f)] = (statistics.median(float(r["wall_s"]) for r in match), len(match), str(src),
                                        bool(match[0].get("entangled_from")))
    return costs


def dependent_makespan(groups: list[tuple[float, list[float]]], workers: int) -> float:
    """Makespan (s) of ``groups`` of (donor cost, [costs of the runs that wait for it]) on
    ``workers``, in the sweep's priority order: the groups as listed, each donor before its
    own dependents; a free worker takes the first run in that order that is ready."""
    tasks = []  # (priority, cost, donor index or None)
    for donor, rest in groups:
        d = len(tasks)
        tasks.append((d, donor, None))
        tasks += [(len(tasks) + k, c, d) for k, c in enumerate(rest)]
    finish = [None] * len(tasks)
    free = [0.0] * workers
    left = list(range(len(tasks)))
    while left:
        w = min(range(workers), key=lambda i: free[i])
        now = free[w]
        ready = [i for i in left if tasks[i][2] is None or (finish[tasks[i][2]] is not None
                                                           and finish[tasks[i][2]] <= now)]
        if not ready:  # wait for the first donor that will be done
            now = min(finish[tasks[i][2]] for i in left if finish[tasks[i][2]] is not None)
            free[w] = now
            continue
        i = ready[0]
        finish[i] = now + tasks[i][1]
        free[w] = finish[i]
        left.remove(i)
    return max(finish)


def makespan(durations: list[float], workers: int) -> float:
    """Longest-first list schedule of ``durations`` (s) on ``workers`` (s)."""
    free = [0.0] * workers
    heapq.heapify(free)
    for d in sorted(durations, reverse=True):
        heapq.heappush(free, heapq.heappop(free) + d)
    return max(free)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", type=Path,
                    help="results.csv of rodwarp sweeps or summary.json of single runs, oldest first")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, help="write the table here too (markdown)")
    ap.add_argument("--no-share", action="store_true",
                    help="every run entangles on its own (rows of branched points are not used)")
    args = ap.parse_args(argv)
    for p in args.results:
        if not p.is_file():
            print(f"error: no results file {p}; pass the results.csv of a rodwarp sweep or a run's summary.json",
                  file=sys.stderr)
            return 2
    costs = point_costs(args.results, shared=not args.no_share)
    lines = ["| alpha | g (m/s^2) | f (Hz) | a/g | median wall per run (s) | runs measured | entangling | source |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    runs, missing = [], []
    by_group: dict = {}
    for g, f in DRIVES:
        for a in ALPHAS:
            ag = 1e-3 * (2 * math.pi * f) ** 2 / g
            c = costs.get((a, g, f))
            if c is None:
                missing.append((a, g, f))
                lines.append(f"| {a:g} | {g:g} | {f:g} | {ag:.3g} | missing | 0 | - | - |")
                continue
            runs += [c[0]] * SEEDS
            by_group.setdefault((a, g), []).append((f, c[0], c[3]))
            lines.append(f"| {a:g} | {g:g} | {f:g} | {ag:.3g} | {c[0]:.0f} | {c[1]} | "
                         f"{'shared (test only)' if c[3] else 'its own'} | {c[2]} |")
    total = sum(runs)
    groups = []
    for (a, g), members in sorted(by_group.items(), key=lambda kv: -kv[0][0]):
        members.sort()
        donor_cost = members[0][1]
        rest = [cost for _, cost, branched in members[1:] if branched]
        alone = [cost for _, cost, branched in members[1:] if not branched]
        for _ in range(SEEDS):
            groups.append((donor_cost, rest))
            groups += [(cost, []) for cost in alone]
    shared = any(rest for _, rest in groups)
    span = dependent_makespan(groups, args.workers) if shared else makespan(runs, args.workers)
    how = ("the sweep's order, a group's tests after its donor" if shared else "longest first")
    bound = " (a lower bound: points missing)" if missing else ""
    lines += ["", f"{len(runs)} runs of {len(ALPHAS) * len(DRIVES) * SEEDS}; run time summed {total / 3600:.2f} h; "
                  f"on {args.workers} workers, {how}: {span / 3600:.2f} h{bound}."]
    if missing:
        lines.append("Missing: " + ", ".join(f"alpha {a:g} at g {g:g}, {f:g} Hz" for a, g, f in missing) + ".")
    text = "\n".join(lines)
    print(text)
    if args.out:
        from rodwarp.rodset.files import atomic_path

        args.out.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(args.out) as tmp:
            tmp.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
