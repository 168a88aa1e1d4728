"""The protocol's outcome against the solver's effort and the adaptive step.

The main job (alpha = 100, f = 10 Hz, g = 0.5, full durations 5 s + 5 s) with three seeds per
setting:

* Gauss-Seidel sweeps per step (``--iterations``) 5, 7, 10, 20, 40 at the default step safety;
* the adaptive step's safety (``--step-safety``: the fraction of a diameter the fastest rod
  may cross per step) 0.25, 0.5, 1, 2, 3 at the default sweeps;
* the fewest steps per drive period (``--steps-per-period``) 10, 20, 40 at the default sweeps
  and safety;
* a reference 10x finer than the default step (a tenth of the default safety, 40 steps per
  period) with 40 sweeps, seed 0.

Outcome at the end: contacts per rod Z, the largest cluster f, the height kept h and the
persistence tau; cost: the run's wall time (one core per run, two runs at a time). The
seed-to-seed spread at a setting is the noise an outcome difference must exceed. Runs go to
``runs/effort`` and are reused when the command is repeated.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks import common

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "runs" / "effort"
SEEDS = (0, 1, 2)
ITERATIONS = (5, 7, 10, 20, 40)
SAFETIES = (0.25, 0.5, 1.0, 2.0, 3.0)
STEPS_PER_PERIOD = (10.0, 20.0, 40.0)
KEYS = ("Z", "f", "h", "tau")


def _defaults():
    from rodwarp.experiments import ProtocolParams

    p = ProtocolParams()
    return p.iterations, p.step_safety, p.steps_per_period


def _settings(quick: bool):
    it0, sf0, sp0 = _defaults()
    out = []
    for it in ITERATIONS:
        out.append({"iterations": it, "step_safety": sf0, "steps_per_period": sp0, "sweep": "iterations"})
    for sf in SAFETIES:
        if sf != sf0:
            out.append({"iterations": it0, "step_safety": sf, "steps_per_period": sp0, "sweep": "safety"})
    for sp in STEPS_PER_PERIOD:
        if sp != sp0:
            out.append({"iterations": it0, "step_safety": sf0, "steps_per_period": sp, "sweep": "spp"})
    seeds = SEEDS[:2] if quick else SEEDS
    runs = [{**s, "seed": seed} for s in out for seed in seeds]
    runs.append({"iterations": 40, "step_safety": sf0 / 10, "steps_per_period": 40.0, "sweep": "reference", "seed": 0})
    return sorted(runs, key=lambda r: (r["sweep"] != "reference", -r["iterations"] / r["step_safety"]))


def _run(p: dict) -> dict:
    out = RUNS / f"it{p['iterations']}_safety{p['step_safety']:g}_spp{p['steps_per_period']:g}_seed{p['seed']}"
    s, failure = common.simulate_once(out, ["--iterations", str(p["iterations"]), "--step-safety",
                                            f"{p['step_safety']:g}", "--steps-per-period", f"{p['steps_per_period']:g}",
                                            "--seed", str(p["seed"])], "effort")
    if failure:
        return {**p, "failure": failure}
    return {**p, "Z": s["contacts_per_rod"], "f": s["largest_cluster_fraction"], "h": s["height_kept"],
            "tau": s["persistence"], "stable": s["stable"], "wall_s": s["wall_time_s"], "steps": s["steps"],
            "max_penetration_over_d": s["max_penetration_over_d"], "failure": None}


def _group(rows, key):
    out = []
    for v in sorted({r[key] for r in rows}):
        sel = [r for r in rows if r[key] == v and not r["failure"]]
        if not sel:
            continue
        g = {key: v, "n": len(sel), "wall_s": common.spread([r["wall_s"] for r in sel]),
             "steps": float(np.median([r["steps"] for r in sel]))}
        for k in KEYS:
            vals = [r[k] for r in sel]
            g[k] = {"mean": float(np.mean(vals)), "min": float(np.min(vals)), "max": float(np.max(vals))}
        out.append(g)
    return out


def run(quick: bool, device: str) -> dict:
    RUNS.mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(max_workers=2) as pool:
        rows = list(pool.map(_run, _settings(quick)))
    it0, sf0, sp0 = _defaults()
    ref = next((r for r in rows if r["sweep"] == "reference" and not r["failure"]), None)
    return {"title": "Protocol outcome against Gauss-Seidel sweeps and the adaptive step (main job, 3 seeds)",
            "rows": rows, "by_iterations": _group([r for r in rows if r["sweep"] == "iterations"], "iterations"),
            "by_safety": _group([r for r in rows if r["sweep"] in ("safety",) or
                                 (r["sweep"] == "iterations" and r["iterations"] == it0)], "step_safety"),
            "by_spp": _group([r for r in rows if r["sweep"] == "spp" or
                              (r["sweep"] == "iterations" and r["iterations"] == it0)], "steps_per_period"),
            "reference": ref, "default_iterations": it0, "default_safety": sf0, "default_spp": sp0,
            "problems": [f"{r['iterations']}/{r['step_safety']}/{r['seed']}: {r['failure']}" for r in rows
                         if r["failure"]]}


def summary(rec: dict) -> list[dict]:
    out = []
    ref = rec["reference"]
    for key, label in (("by_iterations", "iterations"), ("by_safety", "step_safety"),
                       ("by_spp", "steps_per_period")):
        for g in rec.get(key, []):
            out.append({"benchmark": f"main job, {label} = {g[label]:g} ({g['n']} seeds)",
                        "rodwarp": ", ".join(f"{k} {g[k]['mean']:.3f} [{g[k]['min']:.3f}, {g[k]['max']:.3f}]"
                                             for k in KEYS) + f"; wall {g['wall_s']['median']:.0f} s, "
                                                              f"{g['steps']:.0f} steps",
                        "peer": (f"reference (safety {ref['step_safety']:g}, {ref['iterations']} sweeps, seed "
                                 f"{ref['seed']}): " + ", ".join(f"{k} {ref[k]:.3f}" for k in KEYS)
                                 + f"; {ref['wall_s']:.0f} s") if ref else "n/a",
                        "ratio": (ref["wall_s"] / g["wall_s"]["median"]) if ref else None})
    return out


def plot(rec: dict, outdir) -> list[dict]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [("by_iterations", "iterations", rec["default_iterations"]),
            ("by_safety", "step_safety", rec["default_safety"])]
    if rec.get("by_spp"):
        rows.append(("by_spp", "steps_per_period", rec["default_spp"]))
    fig, ax = plt.subplots(len(rows), 4, figsize=(17, 3.5 * len(rows)))
    ref = rec["reference"]
    # the defaults chosen from this chart
    now = dict(zip(("iterations", "step_safety", "steps_per_period"), _defaults()))
    for row, (key, label, dflt) in enumerate(rows):
        groups = rec[key]
        xs = [g[label] for g in groups]
        for k, (name, title) in enumerate((("Z", "contacts per rod Z"), ("f", "largest cluster f"),
                                           ("h", "height kept h"))):
            a = ax[row, k]
            a.errorbar(xs, [g[name]["mean"] for g in groups],
                       yerr=[[g[name]["mean"] - g[name]["min"] for g in groups],
                             [g[name]["max"] - g[name]["mean"] for g in groups]], fmt="o-", capsize=3,
                       label="mean, range over seeds")
            if ref:
                a.axhline(ref[name], color="k", ls=":", label="reference (10x finer step, 40 sweeps)")
            a.axvline(dflt, color="tab:red", ls="-.", lw=1, label=f"default during the run {dflt:g}")
            if now[label] != dflt:
                a.axvline(now[label], color="tab:green", ls="--", lw=1, label=f"default now {now[label]:g}")
            a.set_xscale("log")
            a.set_xlabel(label)
            a.set_ylabel(title)
            a.grid(alpha=0.3)
            a.legend(fontsize=6)
        a = ax[row, 3]
        a.plot(xs, [g["wall_s"]["median"] for g in groups], "s-", color="C1")
        a.axvline(dflt, color="tab:red", ls="-.", lw=1)
        a.set_xscale("log")
        a.set_xlabel(label)
        a.set_ylabel("wall time of the run (s, median)")
        a.grid(alpha=0.3)
    fig.suptitle("main job (alpha 100, 10 Hz, g = 0.5, 5 s + 5 s): outcome and cost against the solver's effort",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(Path(outdir) / "effort.png", dpi=110)
    plt.close(fig)
    return [{"file": "effort.png", "title": "Outcome and cost against sweeps and step safety",
             "reading": "Rows: Gauss-Seidel sweeps per step, the adaptive step's safety, the fewest steps per drive "
                        "period; error bars span the seeds. Command `python -m benchmarks --full --only effort`."}]
