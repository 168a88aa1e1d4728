"""Reproduce the paper's Fig. 4H: largest-cluster fraction f against aspect ratio alpha for
several dynamic loads a/g = 4 pi^2 f^2 A / g (A = 1 mm, g = 0.5 m/s^2).

Each point is one ``rodwarp simulate`` run in its own process (Warp uses one core per
process); finished points are skipped when the command is repeated.  Durations can be
reduced from the paper's 5 s + 5 s; the ones used are written into every output.

    python scripts/reproduce_fig4h.py --entangle-duration 2 --duration 2 --workers 2

Writes OUT/points/alpha{A}_freq{F}/ (full run outputs), OUT/fig4h.csv, OUT/fig4h.json and
OUT/fig4h.png.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--alphas", default="25,50,100,200,300")
    ap.add_argument("--freqs", default="1,10,100")
    ap.add_argument("--entangle-duration", type=float, default=2.0)
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="runs/fig4h")
    args = ap.parse_args(argv)
    out = Path(args.out)
    alphas = [float(a) for a in args.alphas.split(",")]
    freqs = [float(f) for f in args.freqs.split(",")]
    jobs = [(a, f) for a in sorted(alphas, reverse=True) for f in freqs]  # big ones first

    def point(job):
        a, f = job
        d = out / "points" / f"alpha{a:g}_freq{f:g}"
        if (d / "summary.json").exists():
            return job, "skipped"
        cmd = [sys.executable, "-m", "rodwarp.cli", "simulate", "--alpha", f"{a:g}", "--freq", f"{f:g}",
               "--entangle-duration", f"{args.entangle_duration:g}", "--duration", f"{args.duration:g}",
               "--seed", str(args.seed), "--device", "cpu", "--quiet", "--out", str(d)]
        # the script owns its point folders: continue a killed run, else replace what is there
        cmd.append("--resume" if any((d / "checkpoints").glob("ckpt_*.npz")) else "--overwrite")
        t = time.time()
        r = subprocess.run(cmd, capture_output=True, text=True)
        status = "ok" if r.returncode == 0 else r.stderr.strip().splitlines()[-1]
        print(f"alpha={a:g} f={f:g} Hz: {status} ({time.time() - t:.0f} s)", flush=True)
        return job, status

    with ThreadPoolExecutor(max_workers=args.workers) as pool:
        list(pool.map(point, jobs))

    rows = []
    for a, f in jobs:
        p = out / "points" / f"alpha{a:g}_freq{f:g}" / "summary.json"
        if not p.exists():
            continue
        s = json.loads(p.read_text())
        rows.append({"alpha": a, "freq": f, "a_over_g": s["a_over_g"], "n_rods": s["n_rods"],
                     "f": s["largest_cluster_fraction"], "Z": s["contacts_per_rod"], "stable": s["stable"],
                     "max_penetration_over_d": s.get("max_penetration_over_d"), "wall_time_s": s["wall_time_s"],
                     "steps": s["steps"]})
    rows.sort(key=lambda r: (r["a_over_g"], r["alpha"]))
    with open(out / "fig4h.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    meta = {"command": " ".join([Path(sys.argv[0]).as_posix(), *(argv or sys.argv[1:])]),
            "entangle_duration_s": args.entangle_duration, "duration_s": args.duration,
            "paper_durations_s": [5.0, 5.0], "seed": args.seed, "rows": rows}
    (out / "fig4h.json").write_text(json.dumps(meta, indent=2))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    for ag in sorted({round(r["a_over_g"], 6) for r in rows}):
        sel = [r for r in rows if round(r["a_over_g"], 6) == ag]
        ax.plot([r["alpha"] for r in sel], [r["f"] for r in sel], "o-", label=f"a/g = {ag:.3g}")
    ax.axhline(0.5, ls=":", color="0.5", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("aspect ratio alpha")
    ax.set_ylabel("largest contact cluster fraction f")
    ax.set_ylim(0, 1.05)
    ax.set_title(f"Fig. 4H (entangle {args.entangle_duration:g} s, test {args.duration:g} s)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "fig4h.png", dpi=120)
    print(f"wrote {out / 'fig4h.png'}")


if __name__ == "__main__":
    main()
