"""Random settling piles: vertex-steps per second and the time of one step split by stage.

Protocol (issue: "vertex-steps per second on the CPU for random settling piles of 100, 1000
and 10000 rods of 10 vertices ... target for 1000 rods: at least 2e6 vertex-steps/s on one
CPU core"):

* N steel rods (E = 200 GPa, rho = 7850 kg/m^3), l = 1 m, d = 0.01 m (alpha = 100), 10
  vertices, placed by ``random_packing(N, 1.0, 0.01, box)``; box from
  :func:`benchmarks.common.protocol_box` (paper density N0 = 5.4 alpha = 540 rods in
  1 x 1 x 2.5 m; horizontal sides scaled by sqrt(N / 540), never below 1 m; height 2.5 m);
  floor and 4 side walls, gravity (0, 0, -9.81), mu = 0.2;
* ``RodSolver(model)`` with default settings (40 Gauss-Seidel iterations), dt = default_dt();
* warm-up 0.05 s of simulated time (compiles the kernels; the rods start to fall and the
  lowest ones reach the floor); the state is then snapshotted;
* throughput: K steps from the snapshot with profiling OFF (``solver.timings is None``),
  repeated (restoring the snapshot each time); vertex-steps/s = V K / wall;
* stage split: the same K steps with ``solver.reset_timings()`` (synchronises around every
  launch), repeated; host overhead = wall - sum of stages;
* the same with ``iterations`` = 20 and 10 (extra points; iterations is the main cost knob);
* dense point: a settled contact-rich pile (100-rod settled tiles side by side, see
  :func:`benchmarks.common.settled_tile`) of 1000 rods (and 10000 in full mode), default
  solver: the falling pile above has few rod-rod contacts during the timed window.
"""

from __future__ import annotations

import inspect
import time

import numpy as np

from benchmarks import common
from benchmarks.common import fmt, fmt_spread, log

NAME = "pile"
TITLE = "Random settling piles: vertex-steps per second and stage split"
TARGET = 2e6  # vertex-steps/s for 1000 rods on one CPU core
# Stages reported by solver.timings; others the engine adds (e.g. "solve", the fused
# single-launch Gauss-Seidel sweep on the CPU) are recorded too.
STAGES = ("elastics", "broadphase", "narrowphase", "friction", "checks")
STAGE_ORDER = ("elastics", "solve", "friction", "broadphase", "narrowphase", "checks", "host_overhead")
ALPHA = 100.0
DIAMETER = 0.01
WARMUP_S = 0.05


def _steps_for(n_rods: int, quick: bool) -> int:
    if n_rods >= 10000:
        return 10 if quick else 20
    return 50


def _measure(model, solver, snapshot, dt: float, k: int, repeats: int, device: str) -> dict:
    """Throughput (profiling off) and stage split (profiling on) of K steps from ``snapshot``
    (a state and its contact points)."""
    snapshot, snap_points = snapshot
    a = common.new_state_like(model, snapshot)
    b = common.new_state_like(model, snapshot)
    infos = []

    def restore():
        a.copy_from(snapshot)
        common.restore_contacts(solver, snap_points)
        infos.clear()

    def k_steps():
        x, y = a, b
        for _ in range(k):
            info = solver.step(x, y, dt=dt)
            infos.append(info)
            x, y = y, x

    # pre-roll (untimed): the first step of a new solver evaluates energies and allocates
    restore()
    common.advance(solver, a, b, dt, 2)

    solver.timings = None
    wall = common.time_repeats(k_steps, repeats, setup=restore, device=device)
    contacts = [i.n_contacts for i in infos]
    residual = [i.contact_residual for i in infos]
    sweeps = [i.iterations for i in infos]

    stage_samples = {s: [] for s in STAGES}
    prof_wall = []
    for _ in range(repeats):
        restore()
        solver.reset_timings()
        common.sync(device)
        t = time.perf_counter()
        k_steps()
        common.sync(device)
        prof_wall.append(time.perf_counter() - t)
        for s in STAGES:
            stage_samples[s].append(solver.timings.get(s, 0.0))
        extra = set(solver.timings) - set(STAGES)
        for s in extra:
            stage_samples.setdefault(s, []).append(solver.timings[s])
    solver.timings = None

    V = model.n_vertices
    ms_step = common.scale_spread(wall, 1e3 / k)
    stages_ms = {s: common.scale_spread(common.spread(v), 1e3 / k) for s, v in stage_samples.items()}
    host = [w - sum(stage_samples[s][i] for s in stage_samples) for i, w in enumerate(prof_wall)]
    stages_ms["host_overhead"] = common.scale_spread(common.spread(host), 1e3 / k)
    total = sum(v["median"] for v in stages_ms.values())
    fractions = {s: v["median"] / total for s, v in stages_ms.items()}
    return {
        "iterations": solver.iterations,
        "steps_timed": k,
        "repeats": repeats,
        "wall_s": wall,
        "ms_per_step": ms_step,
        "vertex_steps_per_s": common.inverse_spread(wall, V * k),
        "profiled_ms_per_step": common.scale_spread(common.spread(prof_wall), 1e3 / k),
        "stage_ms_per_step": stages_ms,
        "stage_fraction": fractions,
        "contacts_per_step": {"mean": float(np.mean(contacts)), "min": int(min(contacts)), "max": int(max(contacts))},
        "contact_residual": {"mean": float(np.mean(residual)), "max": float(max(residual))},
        "sweeps_per_step": {"mean": float(np.mean(sweeps)), "min": int(min(sweeps)), "max": int(max(sweeps))},
    }


def _pile_point(n_rods: int, quick: bool, device: str, iteration_set) -> dict:
    from rodwarp.sim.solver import RodSolver

    repeats = common.n_repeats(quick)
    box = common.protocol_box(n_rods, ALPHA)
    t = time.perf_counter()
    model = common.pile_model(n_rods, DIAMETER, box, seed=0, device=device)
    pack_s = time.perf_counter() - t
    solver = RodSolver(model)
    dt = solver.default_dt()
    n_warm = int(round(WARMUP_S / dt))
    t = time.perf_counter()
    a = model.state()
    b = common.new_state_like(model, a)
    a, b, info = common.advance(solver, a, b, dt, n_warm)
    warm_s = time.perf_counter() - t
    snapshot = (common.new_state_like(model, a), common.copy_contacts(solver))
    k = _steps_for(n_rods, quick)
    log(f"pile N={n_rods}: packed in {pack_s:.1f} s, warm-up {n_warm} steps in {warm_s:.1f} s, "
        f"{info.n_contacts} contacts; timing {k} steps x {repeats}")
    runs = {}
    for it in iteration_set:
        s = solver if it == solver.iterations else RodSolver(model, iterations=it)
        runs[str(it)] = _measure(model, s, snapshot, dt, k, repeats, device)
        r = runs[str(it)]
        log(f"  iterations {it}: {fmt(r['vertex_steps_per_s']['median'])} vertex-steps/s, "
            f"{fmt(r['ms_per_step']['median'])} ms/step")
    return {
        "n_rods": n_rods,
        "n_vertices": model.n_vertices,
        "vertices_per_rod": 10,
        "box_m": box.tolist(),
        "number_density_per_m3": n_rods / float(np.prod(box)),
        "protocol_density_per_m3": 5.4 * ALPHA / (1.0 * 1.0 * common.PROTOCOL_HEIGHT),
        "packing_s": pack_s,
        "dt_s": dt,
        "warmup_steps": n_warm,
        "warmup_sim_s": n_warm * dt,
        "warmup_wall_s": warm_s,
        "contacts_after_warmup": int(info.n_contacts),
        "explicit_stretch_dt_s": solver.explicit_stretch_dt(),
        "explicit_bending_dt_s": solver.explicit_bending_dt(),
        "max_stable_dt_s": solver.max_stable_dt(),
        "dt_over_explicit_stretch": dt / solver.explicit_stretch_dt(),
        "stable_dt_over_explicit_stretch": solver.max_stable_dt() / solver.explicit_stretch_dt(),
        "default_iterations": solver.iterations,
        "runs": runs,
    }


def _dense_point(n_tiles: int, quick: bool, device: str) -> dict:
    from rodwarp.sim.solver import RodSolver

    tile = common.settled_tile(device)
    model = common.tiled_model(tile, n_tiles, device=device, velocities=True)
    solver = RodSolver(model)
    dt = solver.default_dt()
    snapshot = model.state()
    k = _steps_for(model.n_rods, quick)
    if quick:
        k = min(k, 30)
    repeats = common.n_repeats(quick)
    log(f"dense pile N={model.n_rods}: timing {k} steps x {repeats}")
    r = _measure(model, solver, snapshot, dt, k, repeats, device)
    log(f"  {fmt(r['vertex_steps_per_s']['median'])} vertex-steps/s, {fmt(r['contacts_per_step']['mean'])} contacts/step")
    return {"n_rods": model.n_rods, "n_vertices": model.n_vertices, "n_tiles": n_tiles, "box_m": model.box.tolist(),
            "dt_s": dt, "explicit_stretch_dt_s": solver.explicit_stretch_dt(),
            "dt_over_explicit_stretch": dt / solver.explicit_stretch_dt(), "tile": common.tile_description(tile),
            "default_iterations": solver.iterations, "runs": {str(solver.iterations): r}}


def run(quick: bool, device: str) -> dict:
    from rodwarp.sim.solver import RodSolver

    sizes = [100, 1000] if quick else [100, 1000, 10000]
    default_it = inspect.signature(RodSolver).parameters["iterations"].default
    iteration_set = [default_it, 20, 10]
    points = [_pile_point(n, quick, device, iteration_set) for n in sizes]
    dense = [_dense_point(n // 100, quick, device) for n in ([1000] if quick else [1000, 10000])]

    p1000 = next(p for p in points if p["n_rods"] == 1000)
    vs = p1000["runs"][str(default_it)]["vertex_steps_per_s"]
    target = {"n_rods": 1000, "target_vertex_steps_per_s": TARGET, "measured": vs,
              "ratio_to_target": vs["median"] / TARGET, "met": vs["median"] >= TARGET}
    return {
        "name": NAME,
        "title": TITLE,
        "settings": {
            "alpha": ALPHA, "length_m": common.LENGTH, "diameter_m": DIAMETER, "material": "steel E=200 GPa rho=7850",
            "mu": 0.2, "walls": ["floor", "x-", "x+", "y-", "y+"], "warmup_sim_s": WARMUP_S,
            "box_rule": "horizontal sides max(1, sqrt(N/540)) m, height 2.5 m (paper: 540 rods in 1x1x2.5 for alpha=100)",
            "iterations": iteration_set, "default_iterations": default_it, "sizes": sizes,
            "throughput_pass": "solver.timings = None (no synchronisation)",
            "stage_pass": "solver.reset_timings(): synchronise around every launch; host_overhead = wall - stages",
        },
        "points": points,
        "dense": dense,
        "target": target,
    }


# ----------------------------------------------------------------------------------------------
# report
# ----------------------------------------------------------------------------------------------

def summary(rec: dict) -> list[dict]:
    rows = []
    d = str(rec["settings"]["default_iterations"])
    for p in rec["points"]:
        base = p["runs"][d]
        for it, r in p["runs"].items():
            vs = r["vertex_steps_per_s"]
            label = f"falling pile N={p['n_rods']}, {it} iterations" + (" (default)" if it == d else "")
            split = _split_text(r)
            if it == d and p["n_rods"] == 1000:
                peer, ratio = f"target {fmt(TARGET)} vertex-steps/s", vs["median"] / TARGET
            elif it != d:
                peer, ratio = f"{d} iterations: {fmt(base['vertex_steps_per_s']['median'])}", \
                    vs["median"] / base["vertex_steps_per_s"]["median"]
            else:
                peer, ratio = "—", None
            rows.append({"benchmark": label,
                         "rodwarp": f"{fmt_spread(vs, digits=3)} vertex-steps/s; {fmt(r['ms_per_step']['median'])} ms/step; "
                                    f"{fmt(r['contacts_per_step']['mean'])} contacts/step; {split}",
                         "peer": peer, "ratio": ratio})
    for p in rec["dense"]:
        r = p["runs"][d]
        vs = r["vertex_steps_per_s"]
        rows.append({"benchmark": f"settled (dense) pile N={p['n_rods']}, {d} iterations",
                     "rodwarp": f"{fmt_spread(vs)} vertex-steps/s; {fmt(r['ms_per_step']['median'])} ms/step; "
                                f"{fmt(r['contacts_per_step']['mean'])} contacts/step",
                     "peer": f"target {fmt(TARGET)}" if p["n_rods"] == 1000 else "—",
                     "ratio": vs["median"] / TARGET if p["n_rods"] == 1000 else None})
    return rows


def _split_text(r: dict) -> str:
    fr = r["stage_fraction"]
    keys = [k for k in STAGE_ORDER if k in fr] + sorted(set(fr) - set(STAGE_ORDER))
    return ", ".join(f"{k.replace('_', ' ')} {100 * fr[k]:.0f}%" for k in keys)


def plot(rec: dict, outdir) -> list[dict]:
    plt = common.pyplot()
    d = str(rec["settings"]["default_iterations"])
    its = [str(i) for i in rec["settings"]["iterations"]]
    charts = []

    # ---- stacked stage bars
    groups = [(f"N={p['n_rods']}\nfalling", p, its) for p in rec["points"]] + \
             [(f"N={p['n_rods']}\nsettled", p, [d]) for p in rec["dense"]]
    present = set()
    for _, p, keys in groups:
        for k in keys:
            present |= set(p["runs"][k]["stage_ms_per_step"])
    stages = [s for s in STAGE_ORDER if s in present] + sorted(present - set(STAGE_ORDER))
    palette = {"elastics": "#4c72b0", "solve": "#64b5cd", "friction": "#c44e52", "broadphase": "#dd8452",
               "narrowphase": "#55a868", "checks": "#8172b3", "host_overhead": "#bbbbbb"}
    colors = {s: palette.get(s, f"C{i}") for i, s in enumerate(stages)}
    fig, axes = plt.subplots(1, len(groups), figsize=(3.0 * len(groups) + 1, 4.6))
    axes = np.atleast_1d(axes)
    for ax, (label, p, keys) in zip(axes, groups):
        x = np.arange(len(keys))
        bottom = np.zeros(len(keys))
        for s in stages:
            vals = np.array([p["runs"][k]["stage_ms_per_step"].get(s, {}).get("median") or 0.0 for k in keys])
            ax.bar(x, vals, bottom=bottom, color=colors[s], label=s.replace("_", " "), width=0.7)
            bottom += vals
        for xi, k in zip(x, keys):
            wall = p["runs"][k]["ms_per_step"]["median"]
            ax.plot([xi - 0.35, xi + 0.35], [wall, wall], "k--", lw=1)
        ax.set_xticks(x, [f"{k} it" + ("\n(default)" if k == d else "") for k in keys])
        ax.set_title(label.replace("\n", ", "), fontsize=10)
        ax.set_ylabel("time per step (ms)")
        ax.set_ylim(0, max(bottom.max(), max(p["runs"][k]["ms_per_step"]["median"] for k in keys)) * 1.15)
    h, lab = axes[0].get_legend_handles_labels()
    h.append(plt.Line2D([], [], color="k", ls="--"))
    lab.append("wall per step, profiling off")
    fig.legend(h, lab, loc="lower center", ncol=4, fontsize=8, bbox_to_anchor=(0.5, -0.08))
    fig.suptitle("Time per step by stage (profiled pass, median of repeats) vs pile size and GS iterations", fontsize=11)
    fig.tight_layout()
    f1 = common.save_figure(fig, outdir / f"{NAME}_stages.png")
    p1000 = next((p for p in rec["points"] if p["n_rods"] == 1000), rec["points"][-1])
    r = p1000["runs"][d]
    top = max(r["stage_fraction"], key=r["stage_fraction"].get)
    r10 = p1000["runs"].get("10", r)
    reading = (f"Each panel stacks the profiled time per step by stage (profiling synchronises around every launch); "
               f"the dashed line is the wall time per step with profiling off. At N={p1000['n_rods']} (falling pile) with "
               f"the default {d} iterations a step takes {fmt(r['ms_per_step']['median'])} ms; the largest share is "
               f"{top.replace('_', ' ')} ({100 * r['stage_fraction'][top]:.0f}%); split: {_split_text(r)}. "
               f"The Gauss-Seidel sweeps (stage 'solve' when the engine runs them fused in one launch, otherwise "
               f"'elastics' + 'friction') scale with the iterations actually run "
               f"({fmt(r['sweeps_per_step']['mean'])} on average of at most {d}); with at most 10 iterations the step "
               f"takes {fmt(r10['ms_per_step']['median'])} ms. Broadphase and narrowphase do not depend on iterations. "
               f"The settled panel is a contact-rich pile (about "
               f"{fmt(rec['dense'][0]['runs'][d]['contacts_per_step']['mean']) if rec['dense'] else '—'} rod-rod contacts "
               f"per step) where contact work dominates.")
    charts.append({"file": f1, "title": "Stage split per step", "reading": reading})

    # ---- throughput vs N
    fig, ax = plt.subplots(figsize=(7, 5.2))
    styles = {d: dict(color="C0", lw=2.2, marker="o"), "20": dict(color="C1", marker="s"), "10": dict(color="C2", marker="^")}
    for k in its:
        N = [p["n_rods"] for p in rec["points"]]
        med = np.array([p["runs"][k]["vertex_steps_per_s"]["median"] for p in rec["points"]])
        lo = np.array([p["runs"][k]["vertex_steps_per_s"]["min"] for p in rec["points"]])
        hi = np.array([p["runs"][k]["vertex_steps_per_s"]["max"] for p in rec["points"]])
        ax.errorbar(N, med, yerr=[med - lo, hi - med], capsize=3,
                    label=f"falling pile, {k} iterations" + (" (default)" if k == d else ""), **styles.get(k, {}))
    if rec["dense"]:
        N = [p["n_rods"] for p in rec["dense"]]
        med = np.array([p["runs"][d]["vertex_steps_per_s"]["median"] for p in rec["dense"]])
        lo = np.array([p["runs"][d]["vertex_steps_per_s"]["min"] for p in rec["dense"]])
        hi = np.array([p["runs"][d]["vertex_steps_per_s"]["max"] for p in rec["dense"]])
        ax.errorbar(N, med, yerr=[med - lo, hi - med], capsize=3, color="C3", marker="D", ls=":",
                    label=f"settled pile (contact-rich), {d} iterations (default)")
    ax.axhline(TARGET, color="k", ls="--", lw=1)
    ax.annotate("target at N=1000: 2e6 vertex-steps/s", (1000, TARGET), textcoords="offset points", xytext=(-200, 5),
                fontsize=8)
    ax.axvline(1000, color="0.8", lw=0.8, zorder=0)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rods N (10 vertices each)")
    ax.set_ylabel("vertex-steps per second (median; bars: min–max)")
    ax.set_title(f"Pile throughput, {common.short_device(rec)}", fontsize=10)
    ax.set_ylim(top=max(ax.get_ylim()[1], TARGET * 1.5))
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    ax.grid(True, which="both", alpha=0.3)
    f2 = common.save_figure(fig, outdir / f"{NAME}_throughput.png")
    t = rec["target"]
    best = max(p["runs"]["10"]["vertex_steps_per_s"]["median"] for p in rec["points"] if "10" in p["runs"])
    reading = (f"Vertex-steps per second against pile size (log-log), median of {r['repeats']} repeats with min–max bars. "
               f"At 1000 rods with default settings rodwarp reaches {fmt(t['measured']['median'])} vertex-steps/s, "
               f"{t['ratio_to_target']:.2f}x the 2e6 target ({'met' if t['met'] else 'not met'}). With default settings: "
               + ", ".join(f"N={p['n_rods']}: {fmt(p['runs'][d]['vertex_steps_per_s']['median'])}" for p in rec["points"])
               + f" vertex-steps/s. Lowering the iteration cap is the main lever: the fastest configuration measured "
               f"(10 iterations) reaches {fmt(best)} vertex-steps/s. "
               + (f"The settled pile, with about {fmt(rec['dense'][0]['runs'][d]['contacts_per_step']['mean'])} contacts per "
                  f"step at N={rec['dense'][0]['n_rods']}, runs at "
                  f"{fmt(rec['dense'][0]['runs'][d]['vertex_steps_per_s']['median'])} vertex-steps/s." if rec["dense"] else ""))
    charts.append({"file": f2, "title": "Throughput vs N", "reading": reading})
    return charts
