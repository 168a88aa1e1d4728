"""Stability maps: the largest stable time step against alpha and vertices per rod.

Scene (a small falling pile, so that bending, stretching, rod-rod and rod-wall contacts are
all in play): ``N_RODS`` = 8 steel rods (E = 200 GPa, rho = 7850 kg/m^3), l = 1 m,
d = l / alpha, placed by ``random_packing(8, 1.0, d, (1, 1, 0.65))`` (seed 0) in a
1 x 1 x 0.65 m box with floor and four side walls, gravity (0, 0, -9.81), mu = 0.2.  Every
rod is kinked: Gaussian noise of 0.02 d (seed 1) on every vertex, then the edges rescaled to
their rest length (so the length constraints hold at t = 0), against a straight rest shape;
this excites every bending mode, the highest included, from the first step (a perfectly
straight rod would excite the unstable mode only through round-off).  The rods land on the
floor and on each other within the run (the main rod-rod impacts are at 0.25 .. 0.35 s).

Options (``RodSolver`` / ``Model`` settings that change how the step is integrated):
bending = "explicit" (symplectic bending force in the velocity predictor) or "implicit"
(implicit Euler bending in the Gauss-Seidel sweeps; ``bending="auto"`` is explicit below
0.8 x ``explicit_bending_dt()`` and implicit above, so its largest stable step is the
implicit one), crossed with ``extensible=False`` (exact edge-length constraints) or
``extensible=True`` (compliant stretching, compliance h / (E A), solved in the same
sweeps).  Other settings are the defaults (40 iterations, tolerance 1e-6, penetration limit
0.25 d, default speed limit and energy check).

Search, per option and scene: a run is *stable* when ``solver.step`` (``allow_unstable=True``)
completes the fixed simulated duration T = 0.5 s (the rods land at 0.2 .. 0.4 s) without raising
``SimulationBlowUp`` (non-finite or runaway speed, overlap deeper than the penetration
limit, energy jump).  Bracketing starts at the documented bound of that option
(``max_stable_dt(bending)``) and moves by factors of 2 (up while stable, down while
unstable; at most up to T / 10, at least down to bound / 64), then 3 (quick) or 5 (full)
bisections in log dt between the largest stable and smallest unstable step.  The
record keeps every trial (dt, outcome, steps run, the blow-up message) and, per option, the
bracket [largest stable, smallest unstable] with its ratio to each documented bound.

Bounds drawn on the charts (from a solver of the same scene): ``explicit_bending_dt()``
(2 / omega_max of the bending stencil), ``contact_dt()`` (= ``max_stable_dt("implicit")``:
one diameter per step at the characteristic speed, g dt^2 <= 0.01 d),
``max_stable_dt("explicit")`` (the smaller of the two), ``default_dt()`` (the step a default
``RodSolver`` uses: 0.5 x the bound of bending="auto") and ``explicit_stretch_dt()``
(h_min / sqrt(E / rho): what an explicit axial integrator would need; rodwarp's
constraints and compliant stretching do not).

Axes: alpha = 25, 50, 100, 200, 300 (full mode adds 35, 70, 150) at 10 vertices per rod;
vertices per rod = 5, 10, 20 (full mode adds 7, 14, 28, 40) at alpha = 100; a point on both
axes is searched once.  Cost is dominated by the stable runs of explicit bending at its
small bound (0.5 s / 2.6e-5 s = 19000 steps at 40 vertices, about 1 minute each on one
core), which is why 40 vertices is in the full mode only.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from benchmarks import common
from benchmarks.common import fmt, log

NAME = "stability"
TITLE = "Stability maps: largest stable time step against alpha and vertices per rod"

N_RODS = 8
BOX = (1.0, 1.0, 0.65)  # random_packing needs l + d <= sqrt(3) x the smallest side
NOISE = 0.02  # vertex noise, fraction of d
DURATION = 0.5  # s of simulated time a stable run must complete (the pile lands at 0.2 .. 0.4 s)
ALPHAS = {True: (25, 50, 100, 200, 300), False: (25, 35, 50, 70, 100, 150, 200, 300)}  # quick, full
VERTICES = {True: (5, 10, 20), False: (5, 7, 10, 14, 20, 28, 40)}
BASE_ALPHA = 100
BASE_VERTICES = 10
OPTIONS = (
    ("explicit", False),
    ("explicit", True),
    ("implicit", False),
    ("implicit", True),
)
UP, DOWN = 64.0, 64.0  # search window: bound / DOWN .. min(T / 10, bound * UP)


def option_key(bending: str, extensible: bool) -> str:
    return f"{bending}/{'extensible' if extensible else 'inextensible'}"


def option_label(key: str) -> str:
    bending, ext = key.split("/")
    return f"{bending} bending, {'compliant stretch' if ext == 'extensible' else 'inextensible'}"


def _kinked(points, offsets, amplitude: float, rng) -> np.ndarray:
    """Each rod with Gaussian noise of ``amplitude`` (m) on every vertex, then walked from its
    first vertex with every edge rescaled to its original length, so the edge-length
    constraints hold exactly at t = 0 (the kinks are turning angles of about amplitude / h)."""
    out = np.array(points, float)
    noisy = out + rng.normal(scale=amplitude, size=out.shape)
    for a, b in zip(offsets[:-1], offsets[1:]):
        h = np.linalg.norm(np.diff(out[a:b], axis=0), axis=1)
        x = noisy[a:b].copy()
        for j in range(1, b - a):
            e = noisy[a + j] - x[j - 1]
            x[j] = x[j - 1] + h[j - 1] * e / np.linalg.norm(e)
        out[a:b] = x
    return out


def scene(alpha: float, n_vertices: int, extensible: bool, device: str, seed: int = 0):
    """The small falling pile of the module docstring."""
    from rodwarp.sim.builder import ModelBuilder
    from rodwarp.sim.model import STEEL
    from rodwarp.experiments import random_packing
    from rodwarp.rodset import RodSet

    d = common.LENGTH / alpha
    box = np.array(BOX, float)
    rods = random_packing(N_RODS, common.LENGTH, d, box, seed=seed, n_vertices=n_vertices, device=device)
    pts = _kinked(rods.points, rods.offsets, NOISE * d, np.random.default_rng(seed + 1))
    noisy = RodSet(pts, rods.offsets, rods.radii, rest_points=rods.points, box=rods.box)
    builder = ModelBuilder(noisy, STEEL, gravity=(0.0, 0.0, -9.81), mu=0.2, extensible=extensible, device=device)
    builder.add_box(np.zeros(3), box, walls=("floor", "x-", "x+", "y-", "y+"))
    model = builder.finalize()
    return model


def _trial(model, bending: str, dt: float, duration: float) -> dict:
    """Run ``duration`` seconds at ``dt``; stable unless SimulationBlowUp is raised."""
    from rodwarp.errors import SimulationBlowUp
    from rodwarp.sim.solver import RodSolver

    solver = RodSolver(model, bending=bending, allow_unstable=True)
    a = model.state()
    b = common.new_state_like(model, a)
    n = int(math.ceil(duration / dt - 1e-9))
    t0 = time.perf_counter()
    out = {"dt_s": dt, "steps": n, "stable": True, "steps_run": n, "failure": None, "max_contacts": 0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            for _ in range(n):
                info = solver.step(a, b, dt=dt)
                out["max_contacts"] = max(out["max_contacts"], int(info.n_contacts))
                a, b = b, a
        except SimulationBlowUp as e:
            out.update(stable=False, steps_run=int(e.step), failure=str(e), blowup_time_s=float(e.time))
    out["wall_s"] = time.perf_counter() - t0
    return out


def search(model, bending: str, bound: float, duration: float, n_bisect: int) -> dict:
    """Bracket (factors of 2 from ``bound``) then bisect (in log dt) the largest stable step."""
    cap = min(duration / 10.0, bound * UP)
    floor = bound / DOWN
    trials = []

    def test(dt):
        r = _trial(model, bending, dt, duration)
        trials.append(r)
        return r["stable"]

    lo = hi = None  # largest stable, smallest unstable
    dt = min(bound, cap)
    if test(dt):
        lo = dt
        while lo < cap:
            dt = min(2.0 * lo, cap)
            if test(dt):
                lo = dt
            else:
                hi = dt
                break
    else:
        hi = dt
        while hi > floor:
            dt = hi / 2.0
            if test(dt):
                lo = dt
                break
            hi = dt
    if lo is not None and hi is not None:
        for _ in range(n_bisect):
            dt = math.sqrt(lo * hi)
            if test(dt):
                lo = dt
            else:
                hi = dt
    first_fail = next((t["failure"] for t in trials if t["dt_s"] == hi), None) if hi else None
    return {
        "largest_stable_dt_s": lo,
        "smallest_unstable_dt_s": hi,
        "capped": hi is None,  # stable up to the search cap: the true limit is above it
        "none_stable": lo is None,
        "search_cap_s": cap,
        "search_floor_s": floor,
        "failure_at_smallest_unstable": first_fail,
        "trials": trials,
        "wall_s": float(sum(t["wall_s"] for t in trials)),
    }


def _bounds(model) -> dict:
    from rodwarp.sim.solver import RodSolver

    s = RodSolver(model)
    return {
        "explicit_bending_dt_s": s.explicit_bending_dt(),
        "explicit_stretch_dt_s": s.explicit_stretch_dt(),
        "contact_dt_s": s.contact_dt(),
        "max_stable_dt_explicit_s": s.max_stable_dt("explicit"),
        "max_stable_dt_implicit_s": s.max_stable_dt("implicit"),
        "default_dt_s": s.default_dt(),
        "characteristic_speed_m_s": s.characteristic_speed(),
    }


def _point(alpha: float, n_vertices: int, quick: bool, device: str) -> dict:
    duration = DURATION
    n_bisect = 3 if quick else 5
    point = {"alpha": alpha, "diameter_m": common.LENGTH / alpha, "vertices_per_rod": n_vertices, "options": {}}
    for bending, ext in OPTIONS:
        model = scene(alpha, n_vertices, ext, device)
        bounds = _bounds(model)
        point.setdefault("bounds", bounds)
        bound = bounds["max_stable_dt_explicit_s"] if bending == "explicit" else bounds["max_stable_dt_implicit_s"]
        res = search(model, bending, bound, duration, n_bisect)
        res["documented_bound_s"] = bound
        res["documented_bound"] = f"max_stable_dt('{bending}')"
        lo = res["largest_stable_dt_s"]
        res["ratio_to_bound"] = None if lo is None else lo / bound
        res["ratio_to_explicit_bending"] = None if lo is None else lo / bounds["explicit_bending_dt_s"]
        res["ratio_to_explicit_stretch"] = None if lo is None else lo / bounds["explicit_stretch_dt_s"]
        res["ratio_to_default"] = None if lo is None else lo / bounds["default_dt_s"]
        key = option_key(bending, ext)
        point["options"][key] = res
        hi = res["smallest_unstable_dt_s"]
        log(f"alpha={alpha:g} V={n_vertices} {key}: stable {fmt(lo)} s, unstable {fmt(hi)} s "
            f"(bound {fmt(bound)} s, ratio {fmt(res['ratio_to_bound'])}), {len(res['trials'])} runs in "
            f"{res['wall_s']:.1f} s" + (" [stable up to the cap]" if res["capped"] else ""))
    return point


def run(quick: bool, device: str) -> dict:
    t0 = time.perf_counter()
    cache = {}

    def point(alpha, nv):
        if (alpha, nv) not in cache:
            cache[(alpha, nv)] = _point(alpha, nv, quick, device)
        return cache[(alpha, nv)]

    alpha_points = [point(a, BASE_VERTICES) for a in ALPHAS[quick]]
    vertex_points = [point(BASE_ALPHA, v) for v in VERTICES[quick]]
    problems, notes = [], []
    for p in list(cache.values()):
        for key, r in p["options"].items():
            where = f"alpha={p['alpha']:g}, {p['vertices_per_rod']} vertices, {option_label(key)}"
            if r["none_stable"]:
                problems.append(f"{where}: unstable even at {fmt(r['search_floor_s'])} s "
                                f"(bound {fmt(r['documented_bound_s'])} s): {r['failure_at_smallest_unstable']}")
            elif r["ratio_to_bound"] is not None and r["ratio_to_bound"] < 1.0:
                problems.append(f"{where}: blows up below its documented bound: stable to {fmt(r['largest_stable_dt_s'])} s, "
                                f"bound {fmt(r['documented_bound_s'])} s ({r['documented_bound']}); "
                                f"{r['failure_at_smallest_unstable']}")
            # the default step must be stable for the option the default solver uses (auto ~ implicit above 0.8 eb)
    for p in cache.values():
        d = p["bounds"]["default_dt_s"]
        lo = p["options"][option_key("implicit", False)]["largest_stable_dt_s"]
        if lo is not None and lo < d:
            problems.append(f"alpha={p['alpha']:g}, {p['vertices_per_rod']} vertices: the default step "
                            f"{fmt(d)} s is above the largest stable step {fmt(lo)} s")
    notes.append("bending='auto' is explicit below 0.8 x explicit_bending_dt() and implicit above, so its largest "
                 "stable step is the implicit one (not searched separately).")
    notes.append("extensible=True solves compliant stretching inside the Gauss-Seidel sweeps (implicit); rodwarp has "
                 "no explicit stretching path, so explicit_stretch_dt() is drawn as the limit an explicit axial "
                 "integrator would have, not as a rodwarp bound.")
    return {
        "name": NAME,
        "title": TITLE,
        "settings": {
            "scene": f"{N_RODS} steel rods, l = 1 m, d = l/alpha, random_packing in a {BOX[0]} x {BOX[1]} x {BOX[2]} m "
                     f"box (seed 0), floor + 4 walls, gravity -z, mu 0.2, vertex noise {NOISE} d (seed 1) from the "
                     "straight rest shape",
            "n_rods": N_RODS, "box_m": list(BOX), "noise_fraction_of_d": NOISE, "material": "steel E=200 GPa rho=7850",
            "duration_s": DURATION, "bisections": 3 if quick else 5,
            "bracket": "factors of 2 from the documented bound, window bound/64 .. min(T/10, 64 bound)",
            "stable": "no SimulationBlowUp within the duration (allow_unstable=True; other settings default)",
            "options": [option_key(b, e) for b, e in OPTIONS],
            "alphas": list(ALPHAS[quick]), "vertices": list(VERTICES[quick]), "base_alpha": BASE_ALPHA,
            "base_vertices": BASE_VERTICES,
        },
        "alpha_points": alpha_points,
        "vertex_points": vertex_points,
        "search_wall_s": time.perf_counter() - t0,
        "problems": problems,
        "notes": notes,
    }


# ----------------------------------------------------------------------------------------------
# report
# ----------------------------------------------------------------------------------------------

def _stable_text(r: dict) -> str:
    lo, hi = r["largest_stable_dt_s"], r["smallest_unstable_dt_s"]
    if lo is None:
        return f"unstable down to {fmt(hi)} s"
    if hi is None:
        return f"stable up to the search cap {fmt(lo)} s"
    return f"stable {fmt(lo)} s, blows up at {fmt(hi)} s"


def summary(rec: dict) -> list[dict]:
    """One row per point and bending mode; the two stretch options side by side."""
    rows = []
    seen = set()
    for pts in (rec["alpha_points"], rec["vertex_points"]):
        for p in pts:
            ident = (p["alpha"], p["vertices_per_rod"])
            if ident in seen:
                continue
            seen.add(ident)
            for bending in ("explicit", "implicit"):
                opts = [(ext, p["options"].get(f"{bending}/{ext}")) for ext in ("inextensible", "extensible")]
                opts = [(ext, r) for ext, r in opts if r is not None]
                if not opts:
                    continue
                r0 = opts[0][1]
                text = "; ".join(f"{'inextensible' if ext == 'inextensible' else 'compliant stretch'}: {_stable_text(r)}"
                                 for ext, r in opts)
                es = [r["ratio_to_explicit_stretch"] for _, r in opts if r["ratio_to_explicit_stretch"]]
                ratios = [r["ratio_to_bound"] for _, r in opts if r["ratio_to_bound"] is not None]
                rows.append({
                    "benchmark": f"largest stable dt, alpha={p['alpha']:g}, {p['vertices_per_rod']} vertices, "
                                 f"{bending} bending",
                    "rodwarp": text + (f" ({fmt(min(es))}x the explicit stretch limit)" if es else ""),
                    "peer": f"documented bound {r0['documented_bound']} = {fmt(r0['documented_bound_s'])} s",
                    "ratio": min(ratios) if ratios else None,
                })
    return rows


STYLE = {
    "explicit/inextensible": dict(color="C0", marker="o", mfc="C0"),
    "explicit/extensible": dict(color="C0", marker="s", mfc="none", ls=":"),
    "implicit/inextensible": dict(color="C3", marker="o", mfc="C3"),
    "implicit/extensible": dict(color="C3", marker="s", mfc="none", ls=":"),
}
BOUND_STYLE = {
    "explicit_bending_dt_s": ("explicit_bending_dt()", dict(color="C0", ls="--", lw=1.2)),
    "contact_dt_s": ("contact_dt() = max_stable_dt('implicit')", dict(color="C3", ls="--", lw=1.2)),
    "default_dt_s": ("default_dt()", dict(color="k", ls="-.", lw=1.2)),
    "explicit_stretch_dt_s": ("explicit_stretch_dt() (not a rodwarp bound)", dict(color="0.5", ls=":", lw=1.5)),
}


def _chart(rec, pts, xkey, xlabel, title, path):
    plt = common.pyplot()
    fig, ax = plt.subplots(figsize=(7.6, 5.6))
    x = np.array([p[xkey] for p in pts], float)
    for bkey, (label, st) in BOUND_STYLE.items():
        ax.plot(x, [p["bounds"][bkey] for p in pts], label=label, **st)
    # max_stable_dt('explicit') = min of the two: shade the region below it
    ax.fill_between(x, 1e-7, [p["bounds"]["max_stable_dt_explicit_s"] for p in pts], color="C0", alpha=0.06,
                    label="below max_stable_dt('explicit')")
    keys = [k for k in STYLE if all(k in p["options"] for p in pts)]
    for i, k in enumerate(keys):
        st = dict(STYLE[k])
        ls = st.pop("ls", "-")
        lo = np.array([np.nan if p["options"][k]["largest_stable_dt_s"] is None else p["options"][k]["largest_stable_dt_s"]
                       for p in pts])
        hi = np.array([np.nan if p["options"][k]["smallest_unstable_dt_s"] is None else p["options"][k]["smallest_unstable_dt_s"]
                       for p in pts])
        xs = x * (1.0 + 0.025 * (i - 1.5))  # small offsets so overlapping series stay visible
        ax.plot(xs, lo, ls=ls, ms=7, label=f"largest stable: {option_label(k)}", **st)
        ok = np.isfinite(lo) & np.isfinite(hi)
        ax.vlines(xs[ok], lo[ok], hi[ok], color=st["color"], lw=1, alpha=0.7)
        capped = [j for j, p in enumerate(pts) if p["options"][k]["capped"]]
        for j in capped:
            ax.annotate("", (xs[j], lo[j] * 1.6), (xs[j], lo[j]), arrowprops=dict(arrowstyle="->", color=st["color"]))
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(x, [f"{v:g}" for v in x])
    ax.minorticks_off()
    ax.set_xlabel(xlabel)
    ax.set_ylabel("time step dt (s)")
    lows = [p["bounds"]["explicit_stretch_dt_s"] for p in pts]
    highs = [max(r["smallest_unstable_dt_s"] or r["largest_stable_dt_s"] or 0 for r in p["options"].values()) for p in pts]
    ax.set_ylim(min(lows) / 2, max(highs) * 2.5)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2)
    return common.save_figure(fig, path)


def _reading(rec, pts, what) -> str:
    parts = []
    for k in STYLE:
        vals = [(p, p["options"][k]) for p in pts if k in p["options"]]
        ratios = [r["ratio_to_bound"] for _, r in vals if r["ratio_to_bound"] is not None]
        capped = sum(1 for _, r in vals if r["capped"])
        if not ratios:
            continue
        parts.append(f"{option_label(k)}: largest stable step {fmt(min(ratios))}–{fmt(max(ratios))}x its documented bound"
                     + (f" ({capped} point(s) stable up to the search cap)" if capped else ""))
    es = [r["ratio_to_explicit_stretch"] for p in pts for k, r in p["options"].items()
          if k.startswith("implicit") and r["ratio_to_explicit_stretch"]]
    s = rec["settings"]
    return (f"Largest step that ran {s['duration_s']} s of the falling {s['n_rods']}-rod pile without a blow-up "
            f"against {what} (markers; the vertical bar reaches the smallest step that blew up; an arrow marks a step "
            f"stable up to the search cap), with the documented bounds as lines. " + "; ".join(parts) + ". "
            f"The implicit options run at {fmt(min(es)) if es else '—'}–{fmt(max(es)) if es else '—'}x the explicit "
            f"stretching limit. A ratio >= 1 means the documented bound is safe for this scene.")


def plot(rec: dict, outdir) -> list[dict]:
    dev = common.short_device(rec)
    f1 = _chart(rec, rec["alpha_points"], "alpha", "aspect ratio alpha = l / d (l = 1 m, 10 vertices per rod)",
                f"Largest stable step vs alpha, {rec['settings']['n_rods']}-rod falling pile, steel; {dev}",
                outdir / f"{NAME}_alpha.png")
    f2 = _chart(rec, rec["vertex_points"], "vertices_per_rod", "vertices per rod (alpha = 100, l = 1 m)",
                f"Largest stable step vs vertices per rod, {rec['settings']['n_rods']}-rod falling pile; {dev}",
                outdir / f"{NAME}_vertices.png")
    return [
        {"file": f1, "title": "Stability map against alpha", "reading": _reading(rec, rec["alpha_points"], "alpha")},
        {"file": f2, "title": "Stability map against vertices per rod",
         "reading": _reading(rec, rec["vertex_points"], "vertices per rod")},
    ]
