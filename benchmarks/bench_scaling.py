"""Scaling: time per step against the number of rods, split by stage, with fitted slopes.

Configuration: settled, contact-rich piles of N steel rods (alpha = 100: l = 1 m, d = 0.01 m,
10 vertices), made of N / 100 copies of the settled 100-rod tile
(:func:`benchmarks.common.settled_tile`: RSA in 1 x 1 x 0.6 m, 0.6 s of settling with the
default solver) placed side by side 0.05 m apart (:func:`benchmarks.common.tiled_model`, with
the tile's velocities), floor and outer walls, gravity -z, mu = 0.2; ``RodSolver(model)`` with
default settings (40 Gauss-Seidel iterations, tolerance 1e-6), dt = ``default_dt()``.  Every
N has the same local structure (contacts per rod), so time per step should grow linearly.

N = 100, 300, 1000, 3000, 10000 (quick) and also 30000, 100000 (full), as far as the time
budget allows: before each size the time of one step is predicted from the last two
sizes (log-log) and a size whose predicted cost exceeds the budget is skipped (recorded
with the prediction).

Method, per N: two untimed pre-roll steps (kernel compilation, the first pair-list build,
energy evaluation), then windows of K = 10 steps from the same snapshot, repeated 3 (quick)
/ 5 (full) times (fewer where the budget requires, at least 1).  Every window starts with
the Verlet pair list forced to rebuild (``solver.invalidate_pairs()``), so each
window holds the same number of rebuilds at every N (the tiles are identical copies and
move alike; in free running the list is rebuilt about every 9 steps here, the count is
recorded); K is the same at every N for the same reason:

* throughput pass, profiling off (``solver.timings = None``): wall time per step;
* profiled pass (``solver.reset_timings()``: synchronises around every launch): time per
  stage per step (``elastics``, ``solve`` = the fused Gauss-Seidel sweep on the CPU,
  ``friction``, ``broadphase``, ``narrowphase``, ``checks``) and ``host_overhead`` = wall of
  the profiled pass minus the stages (Python, allocations, host-device copies);
* one profiled step with the pair list rebuilt (``broadphase_rebuild``: the cost of one
  rebuild, which the windows amortise over K steps).

Slopes: least-squares slope of log(time per step) against log N (``common.loglog_slope``)
for the total and for every stage, over all sizes and over N >= 1000 (at small N the fixed
per-launch cost, about 15 us per launch on the CPU, flattens the curve).
"""

from __future__ import annotations

import math
import time

import numpy as np

from benchmarks import common
from benchmarks.common import fmt, log

NAME = "scaling"
TITLE = "Scaling: time per step against the number of rods, by stage"

STAGE_ORDER = ("elastics", "solve", "friction", "broadphase", "narrowphase", "checks", "host_overhead")
SIZES = {True: (100, 300, 1000, 3000, 10000), False: (100, 300, 1000, 3000, 10000, 30000, 100000)}
BUDGET_S = {True: 60.0, False: 300.0}  # most wall seconds one size may take (predicted)
STEPS = 10  # K, the same at every N so that every window holds the same pair-list rebuilds


def _measure(model, dt: float, quick: bool, device: str, budget: float) -> dict:
    from rodwarp.sim.solver import RodSolver

    solver = RodSolver(model)
    snap = model.state()
    no_contacts = solver.contacts()
    a = common.new_state_like(model, snap)
    b = common.new_state_like(model, snap)
    t = time.perf_counter()
    common.advance(solver, a, b, dt, 2)  # pre-roll: compile, build the pair list, energies
    common.sync(device)
    preroll = (time.perf_counter() - t) / 2
    # one more untimed step gives a cleaner per-step estimate than the pre-roll
    a.copy_from(snap)
    common.restore_contacts(solver, no_contacts)
    t = time.perf_counter()
    common.advance(solver, a, b, dt, 1)
    common.sync(device)
    est = time.perf_counter() - t
    repeats = common.n_repeats(quick)
    k = STEPS
    # keep inside the budget: two passes of `repeats` x K steps
    while repeats > 1 and 2 * repeats * k * est > budget:
        repeats -= 1
    infos = []

    def restore():
        a.copy_from(snap)
        common.restore_contacts(solver, no_contacts)
        infos.clear()
        solver.invalidate_pairs()  # every window starts with a pair-list rebuild

    def k_steps():
        x, y = a, b
        for _ in range(k):
            infos.append(solver.step(x, y, dt=dt))
            x, y = y, x

    solver.timings = None
    builds0 = solver.pair_builds
    wall = common.time_repeats(k_steps, repeats, setup=restore, device=device)
    builds_per_window = (solver.pair_builds - builds0) / repeats
    contacts = [i.n_contacts for i in infos]
    sweeps = [i.iterations for i in infos]

    samples: dict[str, list] = {s: [] for s in STAGE_ORDER if s != "host_overhead"}
    prof_wall = []
    for _ in range(repeats):
        restore()
        solver.reset_timings()
        common.sync(device)
        t = time.perf_counter()
        k_steps()
        common.sync(device)
        prof_wall.append(time.perf_counter() - t)
        for s in set(samples) | set(solver.timings):
            samples.setdefault(s, [0.0] * (len(prof_wall) - 1)).append(solver.timings.get(s, 0.0))
    host = [w - sum(v[i] for v in samples.values()) for i, w in enumerate(prof_wall)]
    samples["host_overhead"] = host

    # one step with the pair list rebuilt from scratch
    restore()
    solver.invalidate_pairs()
    solver.reset_timings()
    solver.step(a, b, dt=dt)
    rebuild = dict(solver.timings)
    solver.timings = None

    stages = {s: common.scale_spread(common.spread(v), 1e3 / k) for s, v in samples.items()}
    return {
        "steps_timed": k,
        "repeats": repeats,
        "preroll_s_per_step": preroll,
        "ms_per_step": common.scale_spread(wall, 1e3 / k),
        "vertex_steps_per_s": common.inverse_spread(wall, model.n_vertices * k),
        "profiled_ms_per_step": common.scale_spread(common.spread(prof_wall), 1e3 / k),
        "stage_ms_per_step": stages,
        "pair_builds_per_window": builds_per_window,
        "rebuild_step_stage_ms": {s: 1e3 * v for s, v in rebuild.items()},
        "contacts_per_step": {"mean": float(np.mean(contacts)), "min": int(min(contacts)), "max": int(max(contacts))},
        "sweeps_per_step": {"mean": float(np.mean(sweeps)), "min": int(min(sweeps)), "max": int(max(sweeps))},
    }


def _predict(points, n: int) -> float | None:
    """Predicted wall seconds of one step at n rods from the last two measured sizes."""
    if not points:
        return None
    if len(points) == 1:
        p = points[-1]
        return p["ms_per_step"]["median"] * 1e-3 * n / p["n_rods"]
    p0, p1 = points[-2], points[-1]
    t0, t1 = p0["ms_per_step"]["median"], p1["ms_per_step"]["median"]
    s = max(1.0, math.log(t1 / t0) / math.log(p1["n_rods"] / p0["n_rods"]))
    return t1 * 1e-3 * (n / p1["n_rods"]) ** s


def slopes(points: list[dict]) -> dict:
    ns = [p["n_rods"] for p in points]
    out = {}
    keys = ["total"] + [s for s in STAGE_ORDER if any(s in p["stage_ms_per_step"] for p in points)]
    for key in keys:
        if key == "total":
            ys = [p["ms_per_step"]["median"] for p in points]
        else:
            ys = [p["stage_ms_per_step"].get(key, {}).get("median") for p in points]
        big = [(n, y) for n, y in zip(ns, ys) if n >= 1000]
        out[key] = {"all": common.loglog_slope(ns, ys),
                    "N>=1000": common.loglog_slope([n for n, _ in big], [y for _, y in big])}
    rb = [p["rebuild_step_stage_ms"].get("broadphase") for p in points]
    out["broadphase_rebuild"] = {
        "all": common.loglog_slope(ns, rb),
        "N>=1000": common.loglog_slope([n for n in ns if n >= 1000], [y for n, y in zip(ns, rb) if n >= 1000])}
    return out


def run(quick: bool, device: str) -> dict:
    from rodwarp.sim.solver import RodSolver

    tile = common.settled_tile(device)
    budget = BUDGET_S[quick]
    points, skipped = [], []
    t_start = time.perf_counter()
    for n in SIZES[quick]:
        pred = _predict(points, n)
        if pred is not None:
            # the cheapest measurement: pre-roll (3 steps), 1 repeat of 2 passes x K steps, 1 rebuild step
            need = pred * (3 + 2 * STEPS + 1)
            if need > budget:
                skipped.append({"n_rods": n, "predicted_s_per_step": pred, "predicted_min_wall_s": need,
                                "budget_s": budget})
                log(f"scaling: N={n} skipped: predicted {pred:.2f} s/step, at least {need:.0f} s > budget {budget:.0f} s")
                continue
        t = time.perf_counter()
        model = common.tiled_model(tile, n // 100, device=device, velocities=True)
        build_s = time.perf_counter() - t
        dt = RodSolver(model).default_dt()
        remaining = budget - (pred or 0.0) * 4
        r = _measure(model, dt, quick, device, max(remaining, 1.0))
        r.update({"n_rods": model.n_rods, "n_vertices": model.n_vertices, "n_tiles": n // 100, "dt_s": dt,
                  "model_build_s": build_s, "wall_s": time.perf_counter() - t})
        points.append(r)
        st = r["stage_ms_per_step"]
        log(f"scaling: N={model.n_rods}: {fmt(r['ms_per_step']['median'])} ms/step (K={r['steps_timed']} x "
            f"{r['repeats']}), {fmt(r['contacts_per_step']['mean'])} contacts/step; "
            + ", ".join(f"{s} {fmt(st[s]['median'])}" for s in STAGE_ORDER if s in st) + f"; {r['wall_s']:.0f} s")
    sl = slopes(points)
    problems = []
    tot = sl["total"]["N>=1000"]
    if tot is not None and tot > 1.25:
        problems.append(f"time per step grows faster than linearly: slope {tot:.2f} for N >= 1000")
    return {
        "name": NAME,
        "title": TITLE,
        "settings": {
            "scene": "settled 100-rod tiles (alpha 100, l = 1 m, d = 0.01 m, 10 vertices, steel, mu 0.2) side by side "
                     "0.05 m apart, floor + outer walls, tile velocities kept",
            "solver": "RodSolver(model) defaults (40 iterations, tolerance 1e-6), dt = default_dt()",
            "sizes": list(SIZES[quick]), "budget_s_per_size": budget, "steps_per_window": STEPS,
            "window": "K steps from the same snapshot, the pair list forced to rebuild at the first step",
            "tile": common.tile_description(tile),
            "throughput_pass": "solver.timings = None (no synchronisation)",
            "stage_pass": "solver.reset_timings(): synchronise around every launch; host_overhead = wall - stages",
            "rebuild_step": "one profiled step with solver.invalidate_pairs() (Verlet pair list rebuilt)",
        },
        "points": points,
        "skipped": skipped,
        "slopes": sl,
        "largest_n_rods": points[-1]["n_rods"] if points else None,
        "total_wall_s": time.perf_counter() - t_start,
        "problems": problems,
    }


# ----------------------------------------------------------------------------------------------
# report
# ----------------------------------------------------------------------------------------------

def summary(rec: dict) -> list[dict]:
    rows = []
    sl = rec["slopes"]
    base = rec["points"][0] if rec["points"] else None
    for p in rec["points"]:
        st = p["stage_ms_per_step"]
        split = ", ".join(f"{s.replace('_', ' ')} {fmt(st[s]['median'])}" for s in STAGE_ORDER if s in st)
        per_rod = p["ms_per_step"]["median"] / p["n_rods"]
        rows.append({
            "benchmark": f"settled pile N={p['n_rods']:,} ({p['n_vertices']:,} vertices), default solver",
            "rodwarp": f"{fmt_spread_ms(p['ms_per_step'])} ms/step; {fmt(p['vertex_steps_per_s']['median'])} vertex-steps/s; "
                       f"{fmt(p['contacts_per_step']['mean'])} contacts/step; stages (ms): {split}",
            "peer": f"N={base['n_rods']}: {fmt(base['ms_per_step']['median'] / base['n_rods'] * 1e3)} us/rod/step"
            if base is not None and p is not base else "—",
            "ratio": (per_rod / (base["ms_per_step"]["median"] / base["n_rods"])) if base is not None and p is not base else None,
        })
    for key, v in sl.items():
        rows.append({"benchmark": f"log-log slope of time per step vs N: {key.replace('_', ' ')}",
                     "rodwarp": f"{fmt(v['all'], 3)} (all sizes); {fmt(v['N>=1000'], 3)} (N >= 1000)",
                     "peer": "linear scaling: 1", "ratio": v["N>=1000"]})
    for s in rec.get("skipped", []):
        rows.append({"benchmark": f"N={s['n_rods']:,} skipped",
                     "rodwarp": f"predicted {fmt(s['predicted_s_per_step'])} s/step, at least {fmt(s['predicted_min_wall_s'])} s "
                                f"> budget {fmt(s['budget_s'])} s", "peer": "—", "ratio": None})
    return rows


def fmt_spread_ms(s: dict) -> str:
    return common.fmt_spread(s)


PALETTE = {"total": "k", "elastics": "#4c72b0", "solve": "#64b5cd", "friction": "#c44e52", "broadphase": "#dd8452",
           "narrowphase": "#55a868", "checks": "#8172b3", "host_overhead": "#999999", "broadphase_rebuild": "#dd8452"}


def plot(rec: dict, outdir) -> list[dict]:
    plt = common.pyplot()
    pts = rec["points"]
    sl = rec["slopes"]
    ns = np.array([p["n_rods"] for p in pts], float)
    fig, ax = plt.subplots(figsize=(7.6, 5.8))

    def series(key):
        if key == "total":
            return [p["ms_per_step"] for p in pts]
        if key == "broadphase_rebuild":
            v = [p["rebuild_step_stage_ms"].get("broadphase") for p in pts]
            return [{"median": x, "min": x, "max": x} for x in v]
        return [p["stage_ms_per_step"].get(key, {"median": None}) for p in pts]

    keys = ["total"] + [s for s in STAGE_ORDER if any(s in p["stage_ms_per_step"] for p in pts)] + ["broadphase_rebuild"]
    for key in keys:
        ss = series(key)
        med = np.array([np.nan if s.get("median") in (None, 0) else s["median"] for s in ss], float)
        lo = np.array([np.nan if s.get("min") in (None, 0) else s["min"] for s in ss], float)
        hi = np.array([np.nan if s.get("max") in (None, 0) else s["max"] for s in ss], float)
        v = sl.get(key, {})
        lab = (f"{key.replace('_', ' ')}" + (" (one step, list rebuilt)" if key == "broadphase_rebuild" else "")
               + f": slope {fmt(v.get('N>=1000'), 2)} (N≥1000), {fmt(v.get('all'), 2)} (all)")
        kw = dict(color=PALETTE.get(key, None), marker="o", ms=4)
        if key == "total":
            kw.update(lw=2.4, marker="s", ms=6)
        if key == "broadphase_rebuild":
            kw.update(ls=":", marker="^")
        if key == "host_overhead":
            kw.update(ls="--")
        ok = np.isfinite(med)
        ax.plot(ns[ok], med[ok], label=lab, **kw)
        if key != "broadphase_rebuild":
            okb = ok & np.isfinite(lo) & np.isfinite(hi)
            ax.vlines(ns[okb], lo[okb], hi[okb], color=kw["color"], lw=1, alpha=0.6)
    # slope-1 guide through the total at N = 1000 (or the middle point)
    if len(pts):
        j = int(np.argmin(np.abs(ns - 1000)))
        y0 = pts[j]["ms_per_step"]["median"]
        xs = np.array([ns.min(), ns.max()])
        ax.plot(xs, y0 * xs / ns[j], color="k", lw=0.8, ls=(0, (1, 3)), label="slope 1 (linear) through the total")
    ax.set_xscale("log")
    ax.set_yscale("log")
    cpr = np.mean([p["contacts_per_step"]["mean"] / p["n_rods"] for p in pts]) if pts else float("nan")
    ax.set_xlabel(f"rods N (10 vertices each; settled pile, {cpr:.1f} contact pairs per rod per step)")
    ax.set_ylabel("time per step (ms; median, bars min–max)")
    ax.set_title(f"Time per step by stage vs N, default solver; {common.short_device(rec)}", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=1)
    f = common.save_figure(fig, outdir / f"{NAME}_stages.png")
    big = pts[-1] if pts else None
    if big:
        st = big["stage_ms_per_step"]
        tot = sum(v["median"] for v in st.values())
        top = max(st, key=lambda s: st[s]["median"])
        share = f"{top.replace('_', ' ')} ({100 * st[top]['median'] / tot:.0f}% of the profiled step)"
    reading = ("Time per step (log-log) of settled piles of N rods made of 100-rod tiles, total (throughput pass, "
               "profiling off) and each stage (profiled pass), with least-squares slopes. "
               f"The total grows with slope {fmt(sl['total']['N>=1000'], 3)} for N >= 1000 "
               f"({fmt(sl['total']['all'], 3)} over all sizes; 1 = linear): "
               + ", ".join(f"{k.replace('_', ' ')} {fmt(v['N>=1000'], 2)}" for k, v in sl.items() if k != "total")
               + ". " + (f"At N = {big['n_rods']:,} a step takes {fmt(big['ms_per_step']['median'])} ms "
                         f"({fmt(big['vertex_steps_per_s']['median'])} vertex-steps/s); the largest stage is {share}. "
                         if big else "")
               + "At small N the fixed per-launch cost flattens the curves, hence the N >= 1000 fit. "
               + (f"Skipped (over the time budget): {', '.join(str(s['n_rods']) for s in rec['skipped'])}." if rec.get("skipped") else ""))
    return [{"file": f, "title": "Time per step by stage against N", "reading": reading}]
