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


def point_costs(sources: list[Path]) -> dict:
    """(alpha, g, f) -> (median wall s, runs, source) over the grid, the last source winning."""
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
                w = [float(r["wall_s"]) for r in rows
                     if r.get("wall_s") and r.get("status", "ok") == "ok"
                     and float(r["alpha"]) == a and float(r["gravity"]) == g
                     and abs(float(r["freq"]) / f - 1.0) < 0.02 and float(r.get("static_load") or 0.0) == 0.0]
                if w:
                    costs[(a, g, f)] = (statistics.median(w), len(w), str(src))
    return costs


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
    args = ap.parse_args(argv)
    for p in args.results:
        if not p.is_file():
            print(f"error: no results file {p}; pass the results.csv of a rodwarp sweep or a run's summary.json",
                  file=sys.stderr)
            return 2
    costs = point_costs(args.results)
    lines = ["| alpha | g (m/s^2) | f (Hz) | a/g | median wall per run (s) | runs measured | source |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    runs, missing = [], []
    for g, f in DRIVES:
        for a in ALPHAS:
            ag = 1e-3 * (2 * math.pi * f) ** 2 / g
            c = costs.get((a, g, f))
            if c is None:
                missing.append((a, g, f))
                lines.append(f"| {a:g} | {g:g} | {f:g} | {ag:.3g} | missing | 0 | - |")
                continue
            runs += [c[0]] * SEEDS
            lines.append(f"| {a:g} | {g:g} | {f:g} | {ag:.3g} | {c[0]:.0f} | {c[1]} | {c[2]} |")
    total = sum(runs)
    span = makespan(runs, args.workers)
    bound = " (a lower bound: points missing)" if missing else ""
    lines += ["", f"{len(runs)} runs of {len(ALPHAS) * len(DRIVES) * SEEDS}; run time summed {total / 3600:.2f} h; "
                  f"on {args.workers} workers, longest first: {span / 3600:.2f} h{bound}."]
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
