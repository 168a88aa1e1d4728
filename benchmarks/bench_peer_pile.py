"""A settled pile against the paper's first author's current simulator, side by side.

Scene (the same on both sides): 270 rods of aspect ratio 50 (l = 1 m, d = 0.02 m) placed by
random sequential addition in a closed 1 x 1 x 2.5 m box, g = 0.5 m/s^2, mu = 0.2 (rods and
walls), dt = 1e-3 s fixed, 6000 steps; thread CPU time of each step, median over steps
4000-6000 (the pile has landed and settled), with the contact residual and sweeps used.

* rodwarp: rigid rods (the rod-model rule's choice for this scene), default solver (40 sweeps at most,
  tolerance 1e-5 m/s, over-relaxed Gauss-Seidel), on four packings (seeds 0-3): how fast a
  settled pile converges depends on the pile (at one code, sweeps per step ranged 11-30 over
  the seeds; a change of the last bits of a kernel moves one seed across that range), so the
  figures are medians over the seeds, each seed's own the median over its steps; and elastic
  rods (seed 0) for scale, at 10 vertices and at the resolution rule's 3 (docs/physics.md);
* the peer, rod-dynamics-3d (rigid 6-DOF capsules, projected Gauss-Seidel, 200 sweeps, cfm 0),
  built in a throwaway folder outside the repository and run by the command in
  ``$RODWARP_PEER_PILE`` (it prints one JSON object with ``ms_per_step_median_4000_6000``). Its
  code never enters rodwarp. Without the command the peer is recorded as not run.
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import time

import numpy as np

from benchmarks import common

N_RODS, LENGTH, DIAMETER = 270, 1.0, 0.02
BOX = (1.0, 1.0, 2.5)
DT, STEPS = 1e-3, 6000
WINDOW = (4000, 6000)


RIGID_SEEDS = (0, 1, 2, 3)


def _rodwarp(rod_model: str, device: str, steps: int, seed: int = 0, n_vertices: int = 10) -> dict:
    from rodwarp.experiments import random_packing
    from rodwarp.sim import STEEL, ModelBuilder, RodSolver, State

    rods = random_packing(N_RODS, LENGTH, DIAMETER, BOX, seed=seed, device=device, n_vertices=n_vertices)
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -0.5), mu=0.2, rod_model=rod_model, device=device)
    builder.add_box((0, 0, 0), BOX, walls=("floor", "ceiling", "x-", "x+", "y-", "y+"))
    model = builder.finalize()
    solver = RodSolver(model, allow_unstable=True)  # dt fixed at 1e-3 like the peer's protocol
    control = model.control()
    a, b = model.state(), State(model)
    times, res, sweeps, nc = [], [], [], []
    for _ in range(steps):
        t0 = time.thread_time()
        info = solver.step(a, b, control, dt=DT)
        common.sync(device)
        times.append(time.thread_time() - t0)
        a, b = b, a
        res.append(info.contact_residual)
        sweeps.append(info.iterations)
        nc.append(info.n_contacts)
    lo, hi = int(WINDOW[0] * steps / STEPS), steps
    w = slice(lo, hi)
    return {"rod_model": rod_model, "seed": seed, "ms_per_step_median": 1e3 * float(np.median(times[w])),
            "ms_per_step_spread": common.scale_spread(common.spread(times[w]), 1e3),
            "residual_median": float(np.median(res[w])), "residual_max": float(np.max(res[w])),
            "sweeps_mean": float(np.mean(sweeps[w])), "contacts_median": float(np.median(nc[w])),
            "max_speed_end": float(info.max_speed), "iterations_cap": solver.iterations,
            "tolerance": solver.tolerance, "n_vertices": model.n_vertices}


def _over_seeds(runs: list[dict]) -> dict:
    """The rigid row: medians over the seeds' runs, with every seed's own figures kept."""
    # only what every seed shares is taken from one of them; the rest is over the seeds
    out = {k: runs[0][k] for k in ("rod_model", "iterations_cap", "tolerance", "n_vertices")}
    for k in ("ms_per_step_median", "residual_median", "sweeps_mean", "contacts_median"):
        out[k] = float(np.median([r[k] for r in runs]))
    out["residual_max"] = float(max(r["residual_max"] for r in runs))
    out["seed"] = [r["seed"] for r in runs]
    out["per_seed"] = [{k: r[k] for k in ("seed", "ms_per_step_median", "residual_median", "sweeps_mean",
                                          "contacts_median")} for r in runs]
    # the spread of the pooled steps (every seed's window), for the mean and the early-exit share
    pooled = np.concatenate([r["ms_per_step_spread"]["samples"] for r in runs])
    out["ms_per_step_spread"] = common.spread(pooled)
    return out


def _peer() -> dict | None:
    cmd = os.environ.get("RODWARP_PEER_PILE")
    if not cmd:
        return None
    t = time.perf_counter()
    r = subprocess.run(shlex.split(cmd), capture_output=True, text=True)
    if r.returncode != 0:
        return {"failure": (r.stderr.strip().splitlines() or ["failed"])[-1], "command": cmd}
    out = json.loads(r.stdout.strip().splitlines()[-1])
    # the peer lives in a throwaway folder outside the repository: record its program by name only
    shown = shlex.join([os.path.basename(a) if os.path.isabs(a) else a for a in shlex.split(cmd)])
    out.update({"command": shown, "wall_s": time.perf_counter() - t})
    return out


def run(quick: bool, device: str) -> dict:
    steps = STEPS
    seeds = [_rodwarp("rigid", device, steps, seed) for seed in RIGID_SEEDS]
    # elastic rods at 10 vertices (every elastic run before the resolution rule) and at the rule's
    # choice for this scene: no drive, a sag of 5e-4 d, so 3 vertices (docs/physics.md)
    rows = [_over_seeds(seeds), _rodwarp("elastic", device, steps), _rodwarp("elastic", device, steps, n_vertices=3)]
    peer = _peer()
    problems = []
    r = rows[0]
    if r["residual_median"] >= 1e-5:
        problems.append(f"rigid settled pile: residual median {r['residual_median']:.3g} m/s is not below 1e-5")
    if peer and not peer.get("failure"):
        peer_ms = float(peer["ms_per_step_median_4000_6000"])
        ratio = peer_ms / r["ms_per_step_median"]
        if ratio < 5:
            problems.append(f"only {ratio:.2g}x faster than the peer (target 5x)")
    else:
        ratio = None
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return {"title": "Settled 270-rod pile: rodwarp against rod-dynamics-3d, time per step and residual",
            "rows": rows, "peer": peer, "ratio_peer_over_rodwarp_rigid": ratio, "load_average": load,
            "scene": {"n_rods": N_RODS, "length_m": LENGTH, "diameter_m": DIAMETER, "box_m": BOX, "gravity": 0.5,
                      "mu": 0.2, "dt_s": DT, "steps": steps, "window": WINDOW},
            "problems": problems}


def summary(rec: dict) -> list[dict]:
    peer = rec.get("peer")
    pms = None if not peer or peer.get("failure") else float(peer["ms_per_step_median_4000_6000"])

    def _mean(r):
        return float(np.mean(r["ms_per_step_spread"]["samples"]))

    def _early(r):
        # a step that stopped early costs well under half of one at the sweep cap
        s = np.asarray(r["ms_per_step_spread"]["samples"])
        return float(np.mean(s < 0.5 * np.quantile(s, 0.95)))

    out = []
    for r in rec["rows"]:
        seeds = r.get("per_seed")
        where = (f"{len(seeds)} packings, medians over them; per seed " + ", ".join(
            f"{q['ms_per_step_median']:.2f} ms / {q['sweeps_mean']:.1f} sweeps" for q in seeds)
            + "; ") if seeds else ""
        nv = "" if r["rod_model"] == "rigid" else f", {r['n_vertices'] // N_RODS} vertices a rod"
        out.append({"benchmark": f"settled 270-rod pile, {r['rod_model']} rods{nv} (steps 4000-6000)",
                    "rodwarp": where + f"{r['ms_per_step_median']:.2f} ms/step (median; mean {_mean(r):.2f}, "
                               f"{_early(r):.0%} of steps stop before the cap), residual median "
                               f"{r['residual_median']:.2g} m/s, {r['sweeps_mean']:.1f} sweeps (cap {r['iterations_cap']}), "
                               f"{r['contacts_median']:.0f} contacts",
                    "peer": (f"rod-dynamics-3d: {pms:.2f} ms/step (200 sweeps, cfm 0, residual "
                             f"{peer.get('residual_median')})" if pms else "rod-dynamics-3d: not run here"),
                    "ratio": (pms / r["ms_per_step_median"]) if pms else None})
    return out


def plot(rec: dict, outdir) -> list[dict]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    peer = rec.get("peer")
    names = [f"rodwarp {r['rod_model']}" + ("" if r["rod_model"] == "rigid" else f"\n{r['n_vertices'] // N_RODS} vertices")
             for r in rec["rows"]]
    ms = [r["ms_per_step_median"] for r in rec["rows"]]
    if peer and not peer.get("failure"):
        names.append("rod-dynamics-3d\n(200 sweeps)")
        ms.append(float(peer["ms_per_step_median_4000_6000"]))
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.bar(names, ms, color=["C0", "C2", "C4", "C3"][:len(ms)])
    for k, v in enumerate(ms):
        ax.annotate(f"{v:.2f} ms", (k, v), ha="center", va="bottom", fontsize=8)
    ax.set_ylabel("CPU time per step (ms, median of steps 4000-6000)")
    ax.set_title("settled 270-rod pile (alpha 50, g = 0.5, mu = 0.2, dt = 1e-3)", fontsize=9)
    fig.tight_layout()
    fig.savefig(outdir / "peer_pile.png", dpi=110)
    plt.close(fig)
    return [{"file": "peer_pile.png", "title": "Settled pile against rod-dynamics-3d",
             "reading": "Thread CPU time per step, same scene, same machine, same run. Command "
                        "`RODWARP_PEER_PILE='...' python -m benchmarks --only peer_pile`."}]
