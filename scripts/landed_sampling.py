"""How many samples per drive cycle the landed measures need (docs/verdict.md, "The landed phase").

Runs the stability test of the paper's protocol at the laboratory's scale (l = 50 mm, g = 9.81
m/s^2, rigid rods, scripts/alpha_star_controls.py's entangling) sampled 32 times a cycle under
drives that throw the pile, then takes every 32/K-th sample (K = 1, 2, 4, 8, 16: the samples a
K-per-cycle run would have taken) and compares each cycle's landed h and f, and the landed
measures of the last 5 cycles, with those of the 32 samples. Cost: samples per cycle (each
sample computes the contact clusters and writes a frame). Writes
``benchmarks/results/transition/controls/landed_sampling.{csv,md,png}``.

    python scripts/landed_sampling.py [--runs DIR] [--cycles 20]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "transition" / "controls"
FINE = 32
KS = (1, 2, 4, 8, 16, 32)
#: (alpha, seed, drive): piles the drive throws, one that stands longer and one that falls
CASES = ((100, 0, "l/2 a/g 2.5"), (100, 1, "l/20 a/g 2.5"), (50, 0, "l/2 a/g 1"))


def _run(case, runs: Path, cycles: int) -> Path:
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "scripts"))
    import alpha_star_controls as ctl
    from rodwarp.experiments import ProtocolParams
    from rodwarp.experiments._protocol import run_protocol

    alpha, seed, drive = case
    block = ctl.Block("sampling", "sampling", "lab", "exact", (alpha,), (seed,), (drive,))
    p = ctl.point(block, alpha, seed, drive)
    kw = {k: v for k, v in p.items() if not k.startswith("_") and k != "id"}
    kw.update(cycles=cycles, samples_per_cycle=FINE)
    out = runs / f"alpha{alpha}_seed{seed}_{drive.replace('/', '').replace(' ', '')}"
    if not (out / "summary.json").exists():
        run_protocol(ProtocolParams(**kw), out, progress=False, overwrite=True)
    return out


def _measure(out: Path) -> dict:
    sys.path.insert(0, str(ROOT))
    from rodwarp.experiments import _verdict as vd

    s = json.loads((out / "summary.json").read_text())
    rows = [r for r in csv.DictReader(open(out / "metrics.csv")) if r["stage"] == "stability"]
    t0 = float(s["test_start"]["time"])
    t = np.array([float(r["time"]) for r in rows])
    h = np.array([float(r["height_kept"]) for r in rows])
    f = np.array([float(r["largest_cluster_fraction"]) for r in rows])
    res = {}
    for k in KS:
        step = FINE // k
        idx = np.arange(step - 1, t.size, step)  # the samples a K-per-cycle run takes
        # below LANDED_SAMPLES a run reports no landed measures; here they are computed anyway, to
        # show what a coarser sampling would give
        m = vd.landed(t[idx], t0, s["freq"], h[idx], f[idx], per_cycle=max(k, vd.LANDED_SAMPLES))
        res[k] = m
    return {"summary": s, "by_k": res, "wall": s["wall_time_s"], "samples": t.size}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="runs/landed_sampling", help="folder of the runs (kept for a rerun)")
    ap.add_argument("--cycles", type=int, default=20, help="test cycles per run (default 20)")
    args = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sys.path.insert(0, str(ROOT))
    from rodwarp.rodset.files import save_figure, write_text

    runs = Path(args.runs)
    runs.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    lines = ["case,K,cycle_h_err_median,cycle_h_err_worst,cycle_f_err_median,cycle_f_err_worst,landed_h,landed_f,"
             "landed_h_ref,landed_f_ref,stable,stable_ref"]
    errs = {k: {"h": [], "f": []} for k in KS}
    verdicts = {k: 0 for k in KS}
    for case in CASES:
        m = _measure(_run(case, runs, args.cycles))
        ref = m["by_k"][FINE]
        href = np.array(ref["per_cycle"]["height_kept"])
        fref = np.array(ref["per_cycle"]["largest_cluster_fraction"])
        for k in KS:
            mk = m["by_k"][k]
            hk = np.array(mk["per_cycle"]["height_kept"])
            fk = np.array(mk["per_cycle"]["largest_cluster_fraction"])
            n = min(hk.size, href.size)
            eh = np.abs(hk[:n] - href[:n]) / np.maximum(href[:n], 1e-9)
            ef = np.abs(fk[:n] - fref[:n])
            errs[k]["h"] += eh.tolist()
            errs[k]["f"] += ef.tolist()
            verdicts[k] += int(mk["stable"] == ref["stable"])
            lines.append(",".join(str(x) for x in (
                f"alpha {case[0]} seed {case[1]} {case[2]}", k, np.median(eh), eh.max(), np.median(ef), ef.max(),
                mk["height_kept"], mk["largest_cluster_fraction"], ref["height_kept"],
                ref["largest_cluster_fraction"], mk["stable"], ref["stable"])))
    write_text(OUT / "landed_sampling.csv", "\n".join(lines) + "\n")
    md = ["# Samples per cycle for the landed measures", "",
          f"`python scripts/landed_sampling.py --cycles {args.cycles}`: {len(CASES)} runs of the lab-scale "
          f"stability test (l = 50 mm, g = 9.81 m/s^2, exact law, rigid or elastic by the sag rule) sampled "
          f"{FINE} times a cycle, subsampled to K per cycle; errors against the {FINE}-sample landed values, per "
          f"cycle, pooled over the runs ({len(errs[FINE]['h'])} cycles). Cost: a run's samples "
          "grow as K (each computes the contact clusters and writes a frame).", "",
          "| K | per-cycle landed h: relative error median | worst | per-cycle landed f: error median | worst | "
          f"landed verdict as at K = {FINE} |", "| --- | --- | --- | --- | --- | --- |"]
    for k in KS:
        eh, ef = np.array(errs[k]["h"]), np.array(errs[k]["f"])
        md.append(f"| {k} | {np.median(eh):.3f} | {eh.max():.3f} | {np.median(ef):.3f} | {ef.max():.3f} | "
                  f"{verdicts[k]}/{len(CASES)} |")
    md += ["", f"Wall time of the runs: {time.perf_counter() - t_start:.0f} s (2-core Intel Xeon, beside the "
           "controls study)."]
    write_text(OUT / "landed_sampling.md", "\n".join(md) + "\n")
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for key, lab, c in (("h", "landed h (relative)", "C0"), ("f", "landed f (absolute)", "C1")):
        med = [np.median(errs[k][key]) for k in KS]
        worst = [np.max(errs[k][key]) for k in KS]
        ax.plot(KS, med, "o-", color=c, label=f"{lab}: median")
        ax.plot(KS, worst, "s--", color=c, label=f"{lab}: worst")
    ax.axvline(8, color="grey", ls=":", lw=1)
    ax.set_xscale("log", base=2)
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set_xlabel("samples per drive cycle K (cost grows as K)")
    ax.set_ylabel(f"per-cycle error against K = {FINE}")
    ax.set_title("The landed phase: error against samples per cycle (dotted: the default 8)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, OUT / "landed_sampling.png")
    plt.close(fig)
    print((OUT / "landed_sampling.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
