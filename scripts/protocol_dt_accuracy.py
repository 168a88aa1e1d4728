"""Accuracy of the protocol against the time step: final Z and f at the default step and at
smaller steps (default / 3, default / 10) for alpha = 50 and 200 (reduced durations, stated).

    python scripts/protocol_dt_accuracy.py --entangle-duration 1 --duration 1 --workers 2

Writes OUT/points/..., OUT/dt_accuracy.json and OUT/dt_accuracy.png.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))  # benchmarks.common

from benchmarks.common import command_arg  # noqa: E402


def default_dt(alpha: float) -> float:
    """The step ``rodwarp simulate --alpha A`` picks by default (s)."""
    import numpy as np

    from rodwarp.experiments import ProtocolParams, random_packing, rod_model_rule
    from rodwarp.experiments import plan
    from rodwarp.experiments._protocol import _build, _default_dt

    p = ProtocolParams(alpha=alpha)
    rods = random_packing(p.rods, p.length, p.diameter, np.asarray(p.box) * p.length, seed=p.seed)
    model, solver, _ = _build(p, rods, "cpu", rod_model_rule(p)["rod_model"])
    return _default_dt(plan(p), model, solver)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--alphas", default="50,200")
    ap.add_argument("--factors", default="1,3,10", help="default dt divided by these")
    ap.add_argument("--entangle-duration", type=float, default=1.0)
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="runs/dt_accuracy")
    args = ap.parse_args(argv)
    out = Path(args.out)
    alphas = [float(a) for a in args.alphas.split(",")]
    factors = [float(f) for f in args.factors.split(",")]
    base = {a: default_dt(a) for a in alphas}
    jobs = [(a, k) for k in sorted(factors, reverse=True) for a in alphas]

    def point(job):
        a, k = job
        d = out / "points" / f"alpha{a:g}_dt_div{k:g}"
        if (d / "summary.json").exists():
            return
        cmd = [sys.executable, "-m", "rodwarp.cli", "simulate", "--alpha", f"{a:g}", "--freq", "10",
               "--entangle-duration", f"{args.entangle_duration:g}", "--duration", f"{args.duration:g}",
               "--dt", repr(base[a] / k), "--device", "cpu", "--quiet", "--out", str(d),
               "--overwrite"]  # the script owns its point folders (a finished one is skipped above)
        t = time.time()
        r = subprocess.run(cmd, capture_output=True, text=True)
        print(f"alpha={a:g} dt/{k:g}: {'ok' if r.returncode == 0 else r.stderr.strip()} ({time.time() - t:.0f} s)",
              flush=True)

    with ThreadPoolExecutor(max_workers=args.workers) as pool:
        list(pool.map(point, jobs))

    rows = []
    for a, k in jobs:
        p = out / "points" / f"alpha{a:g}_dt_div{k:g}" / "summary.json"
        if p.exists():
            s = json.loads(p.read_text())
            rows.append({"alpha": a, "dt": base[a] / k, "divisor": k, "Z": s["contacts_per_rod"],
                         "f": s["largest_cluster_fraction"], "stable": s["stable"], "wall_time_s": s["wall_time_s"],
                         "max_penetration_over_d": s.get("max_penetration_over_d")})
    meta = {"command": "python scripts/protocol_dt_accuracy.py " + " ".join(command_arg(a) for a in (argv or sys.argv[1:])),
            "entangle_duration_s": args.entangle_duration, "duration_s": args.duration,
            "default_dt_s": base, "rows": rows}
    (out / "dt_accuracy.json").write_text(json.dumps(meta, indent=2))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(12, 3.6))
    for a in alphas:
        sel = sorted((r for r in rows if r["alpha"] == a), key=lambda r: r["dt"])
        if not sel:
            continue
        dts = [r["dt"] for r in sel]
        ax[0].plot(dts, [r["Z"] for r in sel], "o-", label=f"alpha = {a:g}")
        ax[1].plot(dts, [r["f"] for r in sel], "o-", label=f"alpha = {a:g}")
        ax[2].plot(dts, [r["wall_time_s"] for r in sel], "o-", label=f"alpha = {a:g}")
        for x in ax:
            x.axvline(base[a], ls="--", lw=0.7, color=x.lines[-1].get_color())
    for x, lab in zip(ax, ("final Z (contacts per rod)", "final f (largest cluster)", "wall time (s)")):
        x.set_xscale("log")
        x.set_xlabel("time step dt (s); dashed: default")
        x.set_ylabel(lab)
        x.grid(alpha=0.3)
    ax[2].set_yscale("log")
    ax[0].legend(fontsize=8)
    fig.suptitle(f"protocol outcome vs step (entangle {args.entangle_duration:g} s + test {args.duration:g} s, "
                 f"f = 10 Hz, CPU)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "dt_accuracy.png", dpi=120)


if __name__ == "__main__":
    main()
