"""Elastic rods' resolution: the laboratory outcome and cost against vertices per rod (issue 45).

Scene: the laboratory protocol at alpha 200 with the excitation experiment's rods (l = 50 mm,
d = 0.25 mm, stainless steel, g = 9.81 m/s^2, mu 0.2, the exact contact law, elastic rods): 700
rods poured into a cylinder of radius 0.6 l (the narrowest the protocol takes), which they fill
to 0.46 l as the experiment's 2000 rods fill today's cylinder of radius l, left 1 s to settle,
the cylinder lifted away and the packing left 1 s, then the plate shaken at 5 Hz, 25 mm (a/g
2.5) for 1 s (5 cycles), sampled every 0.05 s. The same command at 3, 4, 6 and 10 vertices
per rod (10: every elastic run before the resolution rule; the rule's choice here is 3), three
seeds each (the packing's seed); 700 rods rather than the experiment's 2000 so that three seeds of
the ten-vertex rods fit in a session (docs/physics.md, "Resolution of elastic rods").

Convergence: which resolution is nearer the converged answer at the protocol's 10 Gauss-Seidel
sweeps. Seed 0, the pour and the lift alone (``--duration 0``), at 3 and 10 vertices with 10,
30 and 100 sweeps and at 16 vertices with 10: the height kept after the lift (its value at 10
sweeps is the shaken runs' own, which share the pour and the lift step for step).

Outcome: after the lift, the height kept and the largest cluster; after the shaking, the
persistence tau (the share of the shaking with f >= 0.8), the largest cluster f, contacts per
rod Z and the landed centroid height y_c / y_c(0) of the last cycle. Cost: each stage's wall time
(one core per run, two runs at a time). Runs go to ``runs/resolution`` and are reused.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks import common

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "runs" / "resolution"
VERTICES = (3, 4, 6, 10)
SEEDS = (0, 1, 2)
SCENE = ["--protocol", "lab", "--alpha", "200", "--length", "0.05", "--gravity", "9.81", "--rod-model", "elastic",
         "--container-radius", "0.6", "--n-rods", "700", "--freq", "5", "--amplitude", "0.025",
         "--pour-duration", "1", "--lift-duration", "1", "--save-every", "0.05", "--fields-every", "0"]
KEYS = ("lift_h", "lift_f", "tau", "f", "Z", "y_c")
#: (vertices, sweeps) of the convergence runs
CONVERGENCE = ((3, 30), (3, 100), (10, 30), (10, 100), (16, 10))


def _run(p: dict) -> dict:
    out = RUNS / f"v{p['vertices']}_seed{p['seed']}"
    s, failure = common.simulate_once(out, [*SCENE, "--duration", "1", "--vertices", str(p["vertices"]), "--seed",
                                            str(p["seed"])], "resolution")
    if failure:
        return {**p, "failure": failure}
    lab = s["lab"]
    landed = lab["shake"]["landed"]["centroid_height_ratio"]
    walls = {k: v.get("wall_s") for k, v in s["dt"].items()}
    return {**p, "failure": None, "n_rods": s["n_rods"],
            "lift_h": lab["lift"]["height_kept_after_lift"], "lift_f": lab["lift"]["largest_cluster_fraction"],
            "tau": lab["shake"]["cohesion"]["persistence"], "f": lab["shake"]["cohesion"]["largest_cluster_fraction"],
            "Z": s["contacts_per_rod"], "y_c": landed[-1] if landed else None,
            "wall_s": s["wall_time_s"], "stage_wall_s": walls, "steps": s["steps"],
            "shake_steps": s["dt"]["shake"]["steps"], "max_penetration_over_d": s["max_penetration_over_d"]}


def _converge(p: dict) -> dict:
    """The height kept after the lift at ``p``'s vertices and sweeps (seed 0, no shaking)."""
    out = RUNS / f"conv_v{p['vertices']}_it{p['iterations']}_seed0"
    s, failure = common.simulate_once(out, [*SCENE, "--duration", "0", "--vertices", str(p["vertices"]), "--iterations",
                                            str(p["iterations"]), "--seed", "0"], "resolution")
    if failure:
        return {**p, "failure": failure}
    return {**p, "failure": None, "lift_h": s["lab"]["lift"]["height_kept_after_lift"], "wall_s": s["wall_time_s"]}


def run(quick: bool, device: str) -> dict:
    RUNS.mkdir(parents=True, exist_ok=True)
    settings = [{"vertices": v, "seed": s} for v in VERTICES for s in (SEEDS[:2] if quick else SEEDS)]
    with ThreadPoolExecutor(max_workers=2) as pool:
        rows = list(pool.map(_run, settings))
        conv = [] if quick else list(pool.map(_converge, [{"vertices": v, "iterations": it} for v, it in CONVERGENCE]))
    # 10 sweeps: the shaken runs' own seed 0 (the same pour and lift)
    conv += [{"vertices": r["vertices"], "iterations": 10, "failure": None, "lift_h": r["lift_h"], "wall_s": None}
             for r in rows if r["seed"] == 0 and not r["failure"] and r["vertices"] in (3, 10)]
    groups = []
    for v in VERTICES:
        sel = [r for r in rows if r["vertices"] == v and not r["failure"]]
        if not sel:
            continue
        g = {"vertices": v, "n": len(sel), "wall_s": common.spread([r["wall_s"] for r in sel]),
             "shake_wall_s": common.spread([r["stage_wall_s"]["shake"] for r in sel])}
        for k in KEYS:
            vals = [r[k] for r in sel if r[k] is not None]
            g[k] = {"mean": float(np.mean(vals)), "min": float(np.min(vals)), "max": float(np.max(vals))}
        groups.append(g)
    return {"title": "Laboratory outcome and cost against vertices per elastic rod (alpha 200, 700 rods, 3 seeds)",
            "scene": "rodwarp simulate " + " ".join(SCENE) + " --duration 1 --vertices N --seed S", "rows": rows,
            "groups": groups, "convergence": sorted(conv, key=lambda c: (c["vertices"], c["iterations"])),
            "problems": [f"v{r['vertices']}/seed{r['seed']}: {r['failure']}" for r in rows if r["failure"]]
                        + [f"convergence v{c['vertices']}/it{c['iterations']}: {c['failure']}" for c in conv
                           if c["failure"]]}


def summary(rec: dict) -> list[dict]:
    ref = next((g for g in rec["groups"] if g["vertices"] == 10), None)
    out = []
    for g in rec["groups"]:
        out.append({"benchmark": f"lab alpha 200, 700 elastic rods, {g['vertices']} vertices ({g['n']} seeds)",
                    "rodwarp": ", ".join(f"{k} {g[k]['mean']:.3f} [{g[k]['min']:.3f}, {g[k]['max']:.3f}]"
                                         for k in KEYS)
                               + f"; wall {g['wall_s']['median']:.0f} s (shaking {g['shake_wall_s']['median']:.0f} s)",
                    "peer": "10 vertices: wall %.0f s" % ref["wall_s"]["median"] if ref else "n/a",
                    "ratio": ref["wall_s"]["median"] / g["wall_s"]["median"] if ref else None})
    for v in sorted({c["vertices"] for c in rec.get("convergence", [])}):
        cs = [c for c in rec["convergence"] if c["vertices"] == v and not c["failure"]]
        out.append({"benchmark": f"convergence: {v} vertices, seed 0, height kept after the lift against sweeps",
                    "rodwarp": ", ".join(f"{c['iterations']} sweeps {c['lift_h']:.3f}" for c in cs),
                    "peer": "n/a", "ratio": None})
    return out


def plot(rec: dict, outdir) -> list[dict]:
    plt = common.pyplot()

    groups = rec["groups"]
    xs = [g["vertices"] for g in groups]
    titles = {"lift_h": "height kept after the lift", "lift_f": "largest cluster after the lift",
              "tau": "persistence tau (shaking)", "f": "largest cluster f (end)", "Z": "contacts per rod Z (end)",
              "y_c": "landed y_c / y_c(0), last cycle"}
    fig, ax = plt.subplots(3, 4, figsize=(17, 10.5))
    for k, key in enumerate(KEYS):
        a = ax.flat[k]
        a.errorbar(xs, [g[key]["mean"] for g in groups],
                   yerr=[[g[key]["mean"] - g[key]["min"] for g in groups],
                         [g[key]["max"] - g[key]["mean"] for g in groups]], fmt="o-", capsize=3,
                   label="mean, range over 3 seeds")
        for r in rec["rows"]:
            if not r["failure"] and r[key] is not None:
                a.plot(r["vertices"], r[key], ".", color="0.5", ms=4)
        a.axvline(3, color="tab:green", ls="--", lw=1, label="the rule's choice (3)")
        a.set_xlabel("vertices per rod")
        a.set_ylabel(titles[key])
        a.grid(alpha=0.3)
        a.legend(fontsize=6)
    for k, (key, label) in enumerate((("wall_s", "whole run"), ("shake_wall_s", "shaking (1 s)"))):
        a = ax.flat[6 + k]
        a.plot(xs, [g[key]["median"] for g in groups], "s-", color="C1")
        a.set_xlabel("vertices per rod")
        a.set_ylabel(f"wall time, {label} (s, median)")
        a.grid(alpha=0.3)
    a = ax.flat[8]
    for v in sorted({c["vertices"] for c in rec.get("convergence", [])}):
        cs = sorted((c for c in rec["convergence"] if c["vertices"] == v and not c["failure"]),
                    key=lambda c: c["iterations"])
        a.plot([c["iterations"] for c in cs], [c["lift_h"] for c in cs], "o-", label=f"{v} vertices")
    a.set_xscale("log")
    a.set_xlabel("Gauss-Seidel sweeps per step (the protocol: 10)")
    a.set_ylabel("height kept after the lift (seed 0)")
    a.grid(alpha=0.3)
    a.legend(fontsize=6)
    for a in ax.flat[9:]:
        a.axis("off")
    fig.suptitle("lab protocol, alpha 200 (l 50 mm, d 0.25 mm, g 9.81), 700 elastic rods, 5 Hz / 25 mm: outcome and "
                 "cost against vertices per rod", fontsize=10)
    fig.tight_layout()
    common.save_figure(fig, Path(outdir) / "resolution.png")  # atomic
    return [{"file": "resolution.png", "title": "Outcome and cost against vertices per elastic rod",
             "reading": "Error bars span three seeds, grey dots are the seeds. Command `python -m benchmarks --full "
                        "--only resolution`."}]
