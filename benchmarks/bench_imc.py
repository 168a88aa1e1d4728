"""The IMC contact law against the exact one: accuracy against cost.

Two measurements, each a chart panel:

* **The law's own answer** (analytic): a 1 m steel rod on a 10 degree incline, mu = 0.4 (below
  the friction angle), spin locked: IMC's smoothed friction makes it creep at
  (2 nu / 15) artanh(tan(theta) / mu) (docs/physics.md, "The IMC contact law"). The relative
  error of the creep speed after 0.3 s against the Gauss-Seidel sweeps per step, for nu = 1e-4,
  1e-3, 1e-2 m/s, elastic (ten vertices) and rigid rods: how many sweeps the stiff smoothed
  friction needs, which the exact law (sticking exactly) does not.
* **The pile** (the cost that matters): the protocol at alpha 50 (270 elastic rods), g = 10,
  entangling 1 s (10 Hz, 5 cm), test 1 s at a/g = 1 (15.92 Hz, 1 mm), seeds 0-2, under the exact
  law and IMC at the three nu, at 10 sweeps (the default) and 40. Cost: wall seconds per simulated
  second (one core per run, two runs at a time); accuracy: the change of the outcome (Z, h) from 10
  to 40 sweeps on the same seed, beside the seed-to-seed spread.

Runs go to ``runs/imc`` and are reused when the command is repeated::

    python -m benchmarks --only imc
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks import common

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "runs" / "imc"
NUS = (1e-4, 1e-3, 1e-2)
SWEEPS_INCLINE = (10, 40, 160, 640, 2560)
SEEDS = (0, 1, 2)
SWEEPS_PILE = (10, 40)
PILE = ["--alpha", "50", "--gravity", "10", "--entangle-duration", "1", "--duration", "1", "--freq", "15.92",
        "--amplitude", "0.001"]
SIMULATED_S = 2.0  # entangling + test
THETA, MU, R = 10.0, 0.4, 0.01


def _incline(nu: float, rod_model: str, sweeps: int) -> dict:
    from rodwarp.rodset import RodSet
    from rodwarp.sim import STEEL, ContactLaw, ModelBuilder, RodSolver, run
    from rodwarp.sim.contact_law import imc_creep_speed
    from rodwarp.testing.scenes import straight_rod, tilted_gravity

    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, R), (1, 0, 0), 1.0, R)], R)
    law = ContactLaw("imc", nu=nu) if nu else ContactLaw("exact")
    builder = ModelBuilder(rods, STEEL, gravity=tilted_gravity(9.81, THETA), mu=MU, rod_contacts=False, rod_model=rod_model,
                           rolling=False, contact_law=law)
    builder.add_plane((0, 0, 1), 0.0, mu=MU, name="floor")
    model = builder.finalize()
    solver = RodSolver(model, iterations=sweeps, tolerance=0.0)
    state = model.state()
    run(solver, state, 0.02, 1e-3)  # compile and settle outside the timing
    t = time.perf_counter()
    state = run(solver, state, 0.28, 1e-3)
    wall = time.perf_counter() - t
    v = float(state.v.numpy()[:, 0].mean())
    exact = float(imc_creep_speed(math.tan(math.radians(THETA)) / MU, nu)) if nu else 0.0
    return {"nu": nu, "rod_model": rod_model, "sweeps": sweeps, "speed": v, "law_speed": exact,
            "rel_error": abs(v - exact) / exact if exact else None, "abs_speed": abs(v),
            "ms_per_step": 1e3 * wall / 280}


def _pile_args(law: str, sweeps: int, seed: int) -> tuple[Path, list[str]]:
    args = [*PILE, "--iterations", str(sweeps), "--seed", str(seed)]
    if law != "exact":
        args += ["--contact-law", "imc", "--imc-nu", law]
    return RUNS / f"pile_{law}_it{sweeps}_seed{seed}", args


def _pile(p: dict) -> dict:
    out, args = _pile_args(p["law"], p["sweeps"], p["seed"])
    s, failure = common.simulate_once(out, args, "imc")
    if failure:
        return {**p, "failure": failure}
    return {**p, "Z": s["contacts_per_rod"], "h": s["height_kept"], "f": s["largest_cluster_fraction"],
            "wall_s": s["wall_time_s"], "steps": s["steps"], "s_per_simulated_s": s["wall_time_s"] / SIMULATED_S,
            "max_penetration_over_d": s["max_penetration_over_d"], "failure": None}


def _laws():
    return ["exact", *(f"{nu:g}" for nu in NUS)]


def _pile_groups(rows):
    out = []
    for law in _laws():
        for sw in SWEEPS_PILE:
            sel = [r for r in rows if r["law"] == law and r["sweeps"] == sw and not r["failure"]]
            if not sel:
                continue
            g = {"law": law, "sweeps": sw, "n": len(sel),
                 "s_per_simulated_s": common.spread([r["s_per_simulated_s"] for r in sel]),
                 "steps": float(np.median([r["steps"] for r in sel]))}
            for k in ("Z", "h", "f"):
                vals = [r[k] for r in sel]
                g[k] = {"mean": float(np.mean(vals)), "min": float(np.min(vals)), "max": float(np.max(vals))}
            # the change to the most sweeps on the same seed, and the seed spread there
            ref = {r["seed"]: r for r in rows if r["law"] == law and r["sweeps"] == max(SWEEPS_PILE)
                   and not r["failure"]}
            for k in ("Z", "h"):
                d = [abs(r[k] - ref[r["seed"]][k]) for r in sel if r["seed"] in ref]
                g[f"d{k}"] = {"median": float(np.median(d)) if d else None, "worst": float(max(d)) if d else None}
                spread = [ref[s][k] for s in ref]
                g[f"noise_{k}"] = float(max(spread) - min(spread)) if len(spread) > 1 else None
            out.append(g)
    return out


def run(quick: bool, device: str) -> dict:
    incline = [_incline(nu, rm, sw) for nu in NUS for rm in ("elastic", "rigid") for sw in SWEEPS_INCLINE]
    incline += [_incline(0.0, rm, sw) for rm in ("elastic", "rigid") for sw in SWEEPS_INCLINE[:2]]
    RUNS.mkdir(parents=True, exist_ok=True)
    todo = [{"law": law, "sweeps": sw, "seed": seed} for sw in sorted(SWEEPS_PILE, reverse=True)
            for law in _laws() for seed in (SEEDS[:2] if quick else SEEDS)]
    with ThreadPoolExecutor(max_workers=2) as pool:
        rows = list(pool.map(_pile, todo))
    return {"title": "IMC against the exact contact law: the law's creep and the pile's cost per simulated second",
            "incline": incline, "pile_rows": rows, "pile": _pile_groups(rows),
            "pile_command": "rodwarp simulate " + " ".join(PILE) + " --iterations N --seed S [--contact-law imc "
                                                                    "--imc-nu NU]",
            "problems": [f"{r['law']}/{r['sweeps']}/{r['seed']}: {r['failure']}" for r in rows if r["failure"]]}


def summary(rec: dict) -> list[dict]:
    out = []
    for nu in NUS:
        for rm in ("elastic", "rigid"):
            sel = {r["sweeps"]: r for r in rec["incline"] if r["nu"] == nu and r["rod_model"] == rm}
            out.append({"benchmark": f"incline creep, IMC nu = {nu:g} m/s, {rm} rod: relative speed error by sweeps",
                        "rodwarp": ", ".join(f"{sw}: {sel[sw]['rel_error']:.2g}" for sw in sorted(sel)),
                        "peer": f"law: {sel[min(sel)]['law_speed']:.3g} m/s", "ratio": None})
    exact = {(g["sweeps"]): g for g in rec["pile"] if g["law"] == "exact"}
    for g in rec["pile"]:
        e = exact.get(g["sweeps"])
        law = "exact" if g["law"] == "exact" else f"IMC nu = {g['law']} m/s"
        out.append({"benchmark": f"pile alpha 50, g = 10, {law}, {g['sweeps']} sweeps ({g['n']} seeds)",
                    "rodwarp": f"{g['s_per_simulated_s']['median']:.1f} s per simulated s "
                               f"[{g['s_per_simulated_s']['min']:.1f}, {g['s_per_simulated_s']['max']:.1f}], "
                               f"{g['steps']:.0f} steps; Z {g['Z']['mean']:.2f}, h {g['h']['mean']:.3f}",
                    "peer": (f"exact: {e['s_per_simulated_s']['median']:.1f} s per simulated s" if e else "n/a"),
                    "ratio": (g["s_per_simulated_s"]["median"] / e["s_per_simulated_s"]["median"]) if e else None})
    return out


def plot(rec: dict, outdir) -> list[dict]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(16, 4.6))
    a = ax[0]
    for k, nu in enumerate(NUS):
        for rm, ls in (("elastic", "-"), ("rigid", "--")):
            sel = sorted((r for r in rec["incline"] if r["nu"] == nu and r["rod_model"] == rm),
                         key=lambda r: r["sweeps"])
            a.plot([r["sweeps"] for r in sel], [max(r["rel_error"], 1e-16) for r in sel], "o" + ls, color=f"C{k}",
                   label=f"nu = {nu:g} m/s, {rm}")
    a.axvline(10, color="tab:red", ls="-.", lw=1, label="protocol default: 10 sweeps")
    a.set_xscale("log")
    a.set_yscale("log")
    a.set_xlabel("Gauss-Seidel sweeps per step (cost)")
    a.set_ylabel("|creep speed - law's| / law's")
    a.set_title("the law's own answer: creep on a 10 deg incline", fontsize=9)
    a.grid(alpha=0.3)
    a.legend(fontsize=6)
    for j, key in enumerate(("h", "Z")):
        a = ax[1 + j]
        for k, law in enumerate(_laws()):
            sel = sorted((g for g in rec["pile"] if g["law"] == law), key=lambda g: g["sweeps"])
            if not sel:
                continue
            xs = [g["s_per_simulated_s"]["median"] for g in sel]
            ys = [g[key]["mean"] for g in sel]
            lo = [g[key]["mean"] - g[key]["min"] for g in sel]
            hi = [g[key]["max"] - g[key]["mean"] for g in sel]
            label = "exact" if law == "exact" else f"IMC nu = {law} m/s"
            a.errorbar(xs, ys, yerr=[lo, hi], fmt="o-", color="k" if law == "exact" else f"C{k - 1}", capsize=3,
                       label=label + " (10, 40 sweeps)")
            for g, x, y in zip(sel, xs, ys):
                a.annotate(str(g["sweeps"]), (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
        a.set_xscale("log")
        a.set_xlabel("wall seconds per simulated second (one core)")
        a.set_ylabel({"h": "height kept h after 1 s of test", "Z": "contacts per rod Z"}[key])
        a.set_title("pile: alpha 50, g = 10, a/g = 1 (mean, range over 3 seeds)", fontsize=9)
        a.grid(alpha=0.3)
        a.legend(fontsize=6)
    fig.suptitle("IMC (DisMech's law) against the exact law: accuracy against cost", fontsize=10)
    fig.tight_layout()
    fig.savefig(Path(outdir) / "imc.png", dpi=110)
    plt.close(fig)
    return [{"file": "imc.png", "title": "IMC against the exact contact law: accuracy against cost",
             "reading": "Left: the creep speed's error against the law's closed form by Gauss-Seidel sweeps (the "
                        "stiff smoothed friction of an elastic rod converges slowly at small nu). Middle and right: "
                        "the pile's outcome against wall time per simulated second for each law at 10 and 40 sweeps, "
                        "range over seeds. Command `python -m benchmarks --only imc`."}]
