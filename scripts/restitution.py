"""Coefficient of restitution of rodwarp's contact laws (issue 51, item 4).

docs/physics.md calls the exact law (Signorini non-penetration and the Coulomb cone, solved by
Gauss-Seidel on velocities) perfectly inelastic; the paper's simulator (DisMech) uses IMC, a
smooth penalty within delta = d / 10, integrated by implicit Euler at dt = 1e-5 s. This script
measures e = (rebound normal speed) / (impact normal speed) of three impacts,

* ``flat``: one straight rod, horizontal, falling onto the floor;
* ``end``: one straight rod falling end-first onto the floor, tilted ``TILT_DEG`` (5) degrees
  from the vertical;
* ``cross``: two straight rods crossed at right angles, one above the other, closing on each
  other along the vertical; both in free fall (gravity on, no floor), so their relative motion
  is that of zero gravity while the step keeps the protocol's gravity bound,

under the exact law at rodwarp's own adaptive step, IMC at that step (both also at 40 sweeps, to
tell the law from unconverged sweeps), and IMC at fixed steps down to DisMech's 1e-5 s (and the
exact law at 1e-5 s, and IMC at 1e-5 s with a DisMech-like softer contact stiffness of 100 rod
weights per delta), for rods of the paper's scale (l = 1 m,
g = 10 m/s^2, steel) and of the laboratory's (l = 50 mm, g = 9.81 m/s^2).

Definitions (the same for every row):

* the normal n is +z (away from the floor; from the lower crossed rod to the upper one), and
  u_n(t) is the normal velocity of the rod's mass centroid (lumped vertex masses; a rigid rod's
  midpoint), for ``cross`` the upper rod's minus the lower rod's;
* a step's normal contact impulse per unit mass is j = du_n - a_free dt (a_free = -g on the floor,
  0 for the crossed pair, which fall together), so u_n changes only where a contact acts; a step
  carries a contact when j / dt > ``CONTACT_G`` (half) of g, whatever the step;
* the impact starts at the first step that carries a contact; the impact speed v_in is the
  largest approach speed -u_n from the start until u_n first turns non-negative after the impact
  starts (or the window ends): the free-flight speed with which the rods enter the contact, which
  IMC's smooth penalty starts to slow before its force reaches half the weight;
* the rebound speed v_out is the largest u_n reached within the window T_w after the impact
  starts (50 ms at the paper's scale, 10 ms at the laboratory's: many IMC contact times, two
  periods of the first bending mode of the l = 1 m alpha-100 rods and four of the lab's alpha-200
  ones, and at least ten of rodwarp's steps); after a separation only gravity acts, so this is
  the normal speed with which the contact ended (less at most g times one step);
* e = max(v_out, 0) / v_in. ``separated`` (the notes' "contact ended") says whether the contact
  impulse fell back to zero within the window and stayed zero for ``QUIET`` (a tenth) of the
  window and at least three steps (the bodies left each other, or, for crossed rods stopped
  inelastically, fall on together without pressing; shorter gaps are chatter within one
  impact); ``contact_time`` is the time from the impact's start to then.

The rods start at the nominal speed a gap 0.5 delta above the floor (or each other; delta =
0.1 d: there IMC's force is 4e-5 of the rod's weight and its stored energy negligible) plus a
phase: ``phase`` x the nominal speed x the first adaptive step, phases 0, 1/3 and 2/3 for every
step above 2e-5 s (so the contact falls at three places within a step; the table gives the
median), 0 alone at 1e-5 s. Falling that gap under gravity raises the impact speed above the
nominal one at 0.1 m/s (to about 0.12-0.22 m/s at l = 1 m); the measured v_in is what each row
reports and what the chart plots.

Rod models: the rod-model rule's own (docs/physics.md, "Two rod models") where it is given, and
rigid capsules at alpha 100 beside the rule's elastic rods to separate the model from the
size. rodwarp's step is the protocol's: ``RodSolver(iterations=10)`` and
``adaptive_dt(safety=2)`` with the overlap feedback, retried by ``adaptive_step``, starting from
the initial speed (as ``rodwarp simulate`` does); without a drive (a drive would cap the step
further, at 20 steps per period). IMC rows lock the spin (the paper's model, the protocol's IMC
default), exact rows roll (the protocol's default). Friction mu = 0.2. Nothing is random: the
scenes are fixed and Warp's CPU kernels run the Gauss-Seidel sweeps in order, so a rerun gives the
same numbers bit for bit (``tests/test_restitution.py``).

Usage::

    python scripts/restitution.py [--quick] [--only-restitution-option] [--out FOLDER]

Writes ``restitution.csv`` (one row per case: medians over the phases), ``restitution.md``
(tables, machine, versions, command) and ``restitution.png`` (e against the impact speed, one
panel per impact) in ``benchmarks/results/restitution/`` (``--out`` to change). ``--quick`` runs
a small subset (one rod configuration, two speeds, three laws; about 10 s) for tests.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import statistics
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "restitution"

#: tilt of the end-first rod from the vertical (degrees)
TILT_DEG = 5.0
#: a step carries a contact when its normal contact acceleration exceeds this fraction of g
CONTACT_G = 0.5
#: the start gap, in IMC distance tolerances delta = 0.1 d (IMC's force there is 4e-5 of the rod's weight)
START_GAP_DELTAS = 0.5
#: IMC's distance tolerance in diameters (the paper's d / 10, rodwarp's default)
DELTA_D = 0.1
#: phases of the start within the first adaptive step, for steps above 2e-5 s
PHASES = (0.0, 1.0 / 3.0, 2.0 / 3.0)
#: the protocol's Gauss-Seidel sweeps and adaptive-step safety (rodwarp simulate's defaults)
ITERATIONS = 10
STEP_SAFETY = 2.0
MU = 0.2
#: DisMech's explicit step (s)
DISMECH_DT = 1e-5
#: a separation: no contact impulse for this fraction of the window, and at least three steps
QUIET = 0.1
#: most steps a case may take (an approach and window at 1e-5 s take a few thousand)
MAX_CASE_STEPS = 200_000

KINDS = ("flat", "end", "cross")
#: the stability test's floor speeds A omega (m/s), marked on the chart (docs/physics.md, "Restitution")
STABILITY_SPEEDS = ((0.1, "A 1 mm, 15.9 Hz"), (0.79, "lab: 25 mm, 5 Hz"), (1.12, "A l/20, 3.56 Hz"),
                    (3.53, "A l/2, 1.125 Hz"))
SPEEDS = (0.1, 0.3, 1.0, 3.0)
QUICK_SPEEDS = (0.3, 1.0)


@dataclass(frozen=True)
class Scale:
    """A rod family.

    Attributes
    ----------
    name : str
        ``paper`` or ``lab``.
    length : float
        Rod length l (m).
    gravity : float
        Gravity's magnitude g (m/s^2).
    window : float
        Window T_w after the impact starts in which the rebound speed is taken (s).
    """

    name: str
    length: float
    gravity: float
    window: float


PAPER = Scale("paper", 1.0, 10.0, 0.05)
LAB = Scale("lab", 0.05, 9.81, 0.01)


@dataclass(frozen=True)
class Rods:
    """One rod configuration: scale, aspect ratio alpha = l / d, rod model and vertices."""

    scale: Scale
    alpha: float
    model: str
    vertices: int
    why: str

    @property
    def label(self) -> str:
        v = f", {self.vertices} v" if self.model == "elastic" else ""
        return f"{self.scale.name} alpha {self.alpha:g} {self.model}{v}"


#: the rod configurations: the rule's model and resolution (docs/physics.md) unless stated
RODS = (
    Rods(PAPER, 25, "rigid", 10, "the rule's (sag 0.0013 d < 0.01 d)"),
    Rods(PAPER, 100, "elastic", 10, "the rule's (sag 0.16 d; 10 vertices at l = 1 m)"),
    Rods(PAPER, 100, "rigid", 10, "forced rigid, to set the rod model apart from the size"),
    Rods(LAB, 25, "rigid", 10, "the rule's (d = 2 mm)"),
    Rods(LAB, 200, "elastic", 3, "the rule's (sag 0.032 d; 3 vertices for a 5 Hz drive)"),
)


@dataclass(frozen=True)
class Law:
    """A contact law and its step.

    Attributes
    ----------
    name : str
        ``exact`` or ``imc``.
    dt : float or None
        Fixed step (s); None: rodwarp's adaptive step.
    stiffness_weights : float or None
        IMC's k_c in rod weights per delta (None: rodwarp's default, 1000).
    iterations : int
        Most Gauss-Seidel sweeps per step (the protocol's 10 unless stated).
    restitution : float
        The exact law's coefficient of restitution option e (0: off, the law's default;
        ``rodwarp simulate --restitution``).
    """

    name: str
    dt: float | None
    stiffness_weights: float | None = None
    iterations: int = ITERATIONS
    restitution: float = 0.0

    @property
    def label(self) -> str:
        step = "rodwarp's step" if self.dt is None else f"dt {self.dt:g} s"
        k = "" if self.stiffness_weights is None else f", k_c {self.stiffness_weights:g} mg/delta"
        it = "" if self.iterations == ITERATIONS else f", {self.iterations} sweeps"
        e = f", e = {self.restitution:g}" if self.restitution else ""
        return f"{self.name}{e}, {step}{k}{it}"


LAWS = (
    Law("exact", None),
    Law("exact", None, iterations=40),
    Law("imc", None),
    Law("imc", None, iterations=40),
    Law("imc", 1e-4),
    Law("imc", DISMECH_DT),
    Law("exact", DISMECH_DT),
    Law("imc", DISMECH_DT, 100.0),
    # the exact law's restitution option (rigid rods only: RESTITUTION_MODELS)
    Law("exact", None, restitution=0.5),
    Law("exact", None, restitution=0.9),
)
#: the rod models the restitution option's rows are measured for (a rigid rod's rebound is the
#: contact's alone; an elastic rod's also rings in bending)
RESTITUTION_MODELS = ("rigid",)
#: the restitution option's laws
RESTITUTION_LAWS = tuple(law for law in LAWS if law.restitution)
QUICK_LAWS = (Law("exact", None), Law("imc", None), Law("imc", DISMECH_DT))


@dataclass(frozen=True)
class Case:
    """One measurement: an impact of ``kind`` at the nominal ``speed`` (m/s) of ``rods`` under
    ``law``, started at ``phase`` of the first step."""

    kind: str
    rods: Rods
    law: Law
    speed: float
    phase: float = 0.0


def _rod(center, direction, length: float, n: int) -> np.ndarray:
    """``n`` vertices (m) of a straight rod of ``length`` (m) centred at ``center`` along ``direction``."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    s = np.linspace(-0.5 * length, 0.5 * length, n)
    return np.asarray(center, float) + s[:, None] * d


def build(case: Case, first_dt: float | None = None):
    """The scene of ``case``: (model, state, bodies), ``bodies`` the vertex indices of the moving
    rod (and of the lower crossed rod) in the model's vertex order.

    ``first_dt`` (s) sets the start gap's phase: the rods start 0.5 delta + ``phase`` x speed x
    ``first_dt`` apart (delta = 0.1 d).
    """
    from rodwarp import RodSet
    from rodwarp.sim import STEEL, ImcLaw, ModelBuilder
    from rodwarp.sim.law_exact import ExactLaw

    rods, law, v = case.rods, case.law, case.speed
    sc = rods.scale
    l, d = sc.length, sc.length / rods.alpha
    r = 0.5 * d
    delta = DELTA_D * d
    gap = START_GAP_DELTAS * delta + case.phase * v * (first_dt or 0.0)
    n = rods.vertices if rods.model == "elastic" else 10
    if case.kind == "flat":
        polys = [_rod((0.0, 0.0, r + gap), (1, 0, 0), l, n)]
        vels = [np.tile((0.0, 0.0, -v), (n, 1))]
    elif case.kind == "end":
        t = math.radians(TILT_DEG)
        axis = np.array([math.sin(t), 0.0, math.cos(t)])
        polys = [_rod((0.0, 0.0, r + gap) + 0.5 * l * axis, axis, l, n)]
        vels = [np.tile((0.0, 0.0, -v), (n, 1))]
    elif case.kind == "cross":
        h = r + 0.5 * gap
        polys = [_rod((0.0, 0.0, h), (1, 0, 0), l, n), _rod((0.0, 0.0, -h), (0, 1, 0), l, n)]
        vels = [np.tile((0.0, 0.0, -0.5 * v), (n, 1)), np.tile((0.0, 0.0, 0.5 * v), (n, 1))]
    else:
        raise ValueError(f"unknown impact kind {case.kind!r}; use one of {', '.join(KINDS)}")
    rs = RodSet.from_polylines(polys, r, velocities=np.concatenate(vels))
    if law.name == "imc":
        weight = STEEL.density * math.pi * r * r * l * sc.gravity
        k = None if law.stiffness_weights is None else law.stiffness_weights * weight / delta
        contact_law = ImcLaw(delta=delta, stiffness=k)
    elif law.restitution:
        contact_law = ExactLaw(restitution=law.restitution)
    else:
        contact_law = "exact"
    b = ModelBuilder(rs, STEEL, gravity=(0.0, 0.0, -sc.gravity), mu=MU, rod_contacts=case.kind == "cross",
                     rod_model=rods.model, rolling=law.name != "imc", contact_law=contact_law, device="cpu")
    if case.kind != "cross":
        b.add_plane((0, 0, 1), 0.0, mu=MU, name="floor")
    model = b.finalize()
    vr = model.vertex_rod_np
    bodies = [np.flatnonzero(vr == k) for k in range(model.n_rods)]
    return model, model.state(), bodies


def _normal_velocity(state, bodies, mass) -> float:
    """u_n (m/s): the first body's centroid z velocity, minus the second's when there are two."""
    vz = state.v.numpy()[:, 2]
    u = [float(mass[b] @ vz[b] / mass[b].sum()) for b in bodies]
    return u[0] - u[1] if len(u) == 2 else u[0]


def _floor_depth(state, radius: float) -> float:
    """Deepest vertex-sphere overlap with the floor z = 0 (m; 0 when none)."""
    return max(0.0, float(radius - state.x.numpy()[:, 2].min()))


def first_adaptive_dt(case: Case) -> float | None:
    """The first step (s) rodwarp's adaptive step takes in ``case``'s scene (None at a fixed step)."""
    if case.law.dt is not None:
        return None
    from rodwarp.sim import RodSolver

    model, state, _ = build(replace(case, phase=0.0))
    solver = RodSolver(model, iterations=case.law.iterations)
    v0 = float(np.linalg.norm(state.velocities(), axis=1).max())
    return solver.adaptive_dt(None, v0, None, safety=STEP_SAFETY)


def measure(case: Case, trace: list | None = None, window: float | None = None) -> dict:
    """Drop, collide and measure one case.

    Returns
    -------
    dict
        ``v_in`` impact speed (m/s), ``v_out`` rebound speed (m/s, signed: the largest u_n in the
        window), ``e`` = max(v_out, 0) / v_in, ``separated`` (bool), ``contact_time`` (s, None
        without separation), ``steps`` (all steps taken), ``refused`` (steps the guard refused),
        ``dt_mean`` (s, over the window), ``depth_over_d`` (deepest overlap in diameters),
        ``wall_s`` (s), ``failure`` (None, or the error's text).

    ``trace``, when given, receives (t (s), u_n (m/s), j (m/s)) after every step; ``window``
    (s) replaces the scale's window.
    """
    from rodwarp.errors import RodwarpError, SimulationBlowUp
    from rodwarp.sim import RodSolver, State

    t_wall = time.perf_counter()
    dt0 = first_adaptive_dt(case)
    model, a, bodies = build(case, dt0)
    b = State(model)
    b.copy_from(a)
    solver = RodSolver(model, iterations=case.law.iterations)
    points = solver.contact_points()
    mass = model.mass_np
    sc = case.rods.scale
    d = sc.length / case.rods.alpha
    a_free = 0.0 if case.kind == "cross" else -sc.gravity
    vmax, prev, overlap = float(np.linalg.norm(a.velocities(), axis=1).max()), None, None
    u = _normal_velocity(a, bodies, mass)
    a_contact = CONTACT_G * sc.gravity
    v_in, turned = -u, False
    t_start = t_sep = t_free = None
    n_free = 0
    v_out, depth, steps, refused, window_steps, window_time = -math.inf, 0.0, 0, 0, 0, 0.0
    # the approach: the rods close the start gap (0.5 delta + at most one step's travel) at the
    # nominal speed, under gravity at most sqrt(2 g gap); a generous bound on its time
    gap = START_GAP_DELTAS * DELTA_D * d + case.phase * case.speed * (dt0 or 0.0)
    t_approach = 10.0 * gap / case.speed + 10.0 * math.sqrt(2.0 * gap / sc.gravity) + 10.0 * (dt0 or 0.0)
    failure = None
    try:
        while True:
            if case.law.dt is None:
                dt = solver.adaptive_dt(None, vmax, prev, safety=STEP_SAFETY, overlap=overlap)
                info, dt, k = solver.adaptive_step(a, b, None, points, dt)
                refused += k
            else:
                dt = case.law.dt
                solver.collide(a, None, dt, points)
                info = solver.step(a, b, None, points, dt)
            a, b = b, a
            steps += 1
            vmax, prev, overlap = info.max_speed, dt, info.max_overlap
            u_new = _normal_velocity(a, bodies, mass)
            j = u_new - u - a_free * dt
            if trace is not None:
                trace.append((a.time, u_new, j))
            touching = j > a_contact * dt
            if t_start is None and touching:
                t_start = a.time - dt
            if not turned:
                v_in = max(v_in, -u_new)
                turned = t_start is not None and u_new >= 0.0
            depth = max(depth, info.max_overlap, _floor_depth(a, 0.5 * d) if case.kind != "cross" else 0.0)
            if t_start is not None:
                v_out = max(v_out, u_new)
                window_steps += 1
                window_time += dt
                if touching:
                    t_free, n_free = None, 0
                elif t_sep is None:
                    # a run of steps without a contact impulse: a separation once it lasts
                    t_free = a.time - dt if t_free is None else t_free
                    n_free += 1
                    if n_free >= 3 and a.time - t_free >= QUIET * (window or sc.window):
                        t_sep = t_free - t_start
                if a.time >= t_start + (window or sc.window):
                    break
            elif a.time > t_approach:
                failure = f"no impact within {t_approach:.3g} s"
                break
            if steps >= MAX_CASE_STEPS:
                failure = f"more than {MAX_CASE_STEPS} steps"
                break
            u = u_new
    except (RodwarpError, SimulationBlowUp) as err:  # a blow-up or a refused step: recorded, not fatal
        failure = str(err).splitlines()[0].split(';')[0]
    if t_start is None and failure is None:
        failure = "no impact"
    e = None if failure else max(v_out, 0.0) / v_in
    return {"v_in": v_in if t_start is not None else None, "v_out": None if v_out == -math.inf else v_out, "e": e,
            "separated": t_sep is not None,
            "contact_time": t_sep, "steps": steps, "refused": refused,
            "dt_mean": window_time / window_steps if window_steps else None, "depth_over_d": depth / d,
            "wall_s": time.perf_counter() - t_wall, "failure": failure}


def cases(quick: bool = False, only_restitution: bool = False) -> list[list[Case]]:
    """The measurement plan: one list of cases (its phases) per row of the results
    (``only_restitution``: the restitution option's rows alone)."""
    rods = RODS[1:2] if quick else RODS
    laws = RESTITUTION_LAWS if only_restitution else QUICK_LAWS if quick else LAWS
    speeds = QUICK_SPEEDS if quick else SPEEDS
    plan = []
    for rc in rods:
        for kind in KINDS:
            for law in laws:
                if law.restitution and rc.model not in RESTITUTION_MODELS:
                    continue
                phases = (0.0,) if (quick or (law.dt is not None and law.dt <= 2e-5)) else PHASES
                for v in speeds:
                    plan.append([Case(kind, rc, law, v, p) for p in phases])
    return plan


def summarise(group: list[Case], results: list[dict]) -> dict:
    """One row of the results from a case's phases (medians; the spread of e in e_min, e_max)."""
    c = group[0]
    rc, law, sc = c.rods, c.law, c.rods.scale
    ok = [r for r in results if r["failure"] is None]
    med = lambda k: statistics.median(r[k] for r in ok) if ok else None  # noqa: E731
    seps = [r["contact_time"] for r in ok if r["separated"]]
    notes = []
    if any(r["failure"] for r in results):
        notes.append("; ".join(f"phase {g.phase:.2f}: {r['failure']}" for g, r in zip(group, results) if r["failure"]))
    n_sep = sum(r["separated"] for r in ok)
    if ok:
        notes.append("contact ended" if n_sep == len(ok) else "stayed in contact" if n_sep == 0
                     else f"contact ended in {n_sep} of {len(ok)} phases")
    if any(r["refused"] for r in ok):
        notes.append(f"{sum(r['refused'] for r in ok)} steps refused by the guard and retried")
    d = sc.length / rc.alpha
    return {"impact": c.kind, "law": law.name, "dt_s": "adaptive" if law.dt is None else law.dt,
            "iterations": law.iterations, "stiffness_weights_per_delta": law.stiffness_weights or 1000.0,
            "restitution": law.restitution,
            "scale": sc.name, "length_m": sc.length, "diameter_m": d, "alpha": rc.alpha, "gravity_m_s2": sc.gravity,
            "model": rc.model, "vertices": rc.vertices if rc.model == "elastic" else 2,
            "nominal_speed_m_s": c.speed, "impact_speed_m_s": med("v_in"), "rebound_speed_m_s": med("v_out"),
            "e": med("e"), "e_min": min(r["e"] for r in ok) if ok else None,
            "e_max": max(r["e"] for r in ok) if ok else None, "phases": len(group),
            "contact_time_s": statistics.median(seps) if seps else None,
            "mean_dt_s": med("dt_mean"), "steps": med("steps"), "max_depth_over_d": med("depth_over_d"),
            "wall_s": sum(r["wall_s"] for r in results), "notes": "; ".join(notes)}


def run_plan(plan: list[list[Case]], progress: bool = True) -> list[dict]:
    """Measure every case of ``plan`` (one process, one Warp CPU thread) and summarise its rows."""
    rows = []
    for i, group in enumerate(plan):
        res = [measure(c) for c in group]
        rows.append(summarise(group, res))
        if progress:
            r = rows[-1]
            print(f"[{i + 1}/{len(plan)}] {group[0].rods.label}, {r['impact']}, {group[0].law.label}, "
                  f"v {r['nominal_speed_m_s']:g}: e = {_f(r['e'])} (v_in {_f(r['impact_speed_m_s'])}) "
                  f"{r['notes']} [{r['wall_s']:.1f} s]", flush=True)
    return rows


def _f(x, digits: int = 3) -> str:
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    if x == 0:
        return "0"
    if abs(x) >= 1e-3:
        return f"{x:.{digits}g}"
    return f"{x:.{digits - 1}e}"


CSV_COLUMNS = ("impact", "law", "dt_s", "iterations", "stiffness_weights_per_delta", "model", "alpha", "scale",
               "length_m", "diameter_m", "gravity_m_s2", "vertices", "nominal_speed_m_s", "impact_speed_m_s",
               "rebound_speed_m_s", "e", "e_min", "e_max", "phases", "contact_time_s", "mean_dt_s", "steps",
               "max_depth_over_d", "wall_s", "notes", "restitution")


def to_csv(rows: list[dict]) -> str:
    """The rows as CSV text (``CSV_COLUMNS``)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow(r["_raw"] if "_raw" in r else {k: ("" if r[k] is None else r[k]) for k in CSV_COLUMNS})
    return buf.getvalue()


def _law_key(r: dict) -> str:
    step = "rodwarp's step" if r["dt_s"] == "adaptive" else f"dt {r['dt_s']:g} s"
    k = "" if r["stiffness_weights_per_delta"] == 1000.0 else f", k_c {r['stiffness_weights_per_delta']:g} mg/delta"
    it = "" if int(r["iterations"]) == ITERATIONS else f", {r['iterations']} sweeps"
    e = f", e = {float(r['restitution']):g}" if float(r.get("restitution") or 0) else ""
    return f"{r['law']}{e}, {step}{k}{it}"


def _rods_key(r: dict) -> str:
    v = f", {r['vertices']} v" if r["model"] == "elastic" else ""
    return f"{r['scale']} alpha {r['alpha']:g} {r['model']}{v}"


def markdown(rows: list[dict], meta: dict) -> str:
    """``restitution.md``: how it was made, then e per rod configuration and impact."""
    v = meta["versions"]
    speeds = sorted({r["nominal_speed_m_s"] for r in rows})
    windows = ", ".join(f"{1e3 * sc.window:g} ms at l = {sc.length:g} m" for sc in (PAPER, LAB))
    low = [r["impact_speed_m_s"] for r in rows if r["nominal_speed_m_s"] == min(speeds) and r["impact_speed_m_s"]]
    dirty = meta["engine_dirty"]
    lines = ["# Coefficient of restitution of rodwarp's contact laws", "",
             f"Generated by `{meta['command']}` on {meta['date']} in {meta['cpu_s']:.0f} s of one CPU core "
             f"(rodwarp {v['rodwarp']}, git {v['git']['commit']}, warp {v['warp']}, numpy {v['numpy']}, "
             f"Python {v['python']}; {meta['device']}). The engine this script uses (rodwarp/sim, kernels) was "
             + ("modified in the working tree: " + ", ".join(dirty) if dirty else "as committed")
             + ". Deterministic: no random choice; the scenes are fixed and the CPU sweeps run in order."
             + (f" Rows other than the restitution option's (exact, e = ...) are kept from the results "
                f"{meta['merged'][0].lower()}{meta['merged'][1:]}." if meta.get("merged") else ""), "",
             "e = max(v_out, 0) / v_in: v_in is the largest approach speed of the rod's mass centroid along the "
             "normal (for crossed rods, the upper rod's centroid relative to the lower's) before the rebound, v_out "
             "the largest separating normal speed of the same within the window after the impact starts (the first "
             f"step whose contact acceleration exceeds g / 2; {windows}), which for a rod that leaves is its normal "
             "speed when the contact ended. The speeds in the column heads are nominal; "
             "the measured v_in (median) is in the CSV and the chart"
             + (f" ({min(low):.3g}-{max(low):.3g} m/s at the nominal {min(speeds):g}: the rods start 0.05 d apart, "
                "outside IMC's range, and gravity acts on the way)" if low else "")
             + ". Medians over 3 start phases within the first step for steps above 2e-5 s (the spread "
             "is e_min-e_max in the CSV). Impacts: flat = a horizontal rod onto the floor; end = a rod "
             f"{TILT_DEG:g} degrees from the vertical, end-first onto the floor; cross = two rods crossed at right "
             "angles closing along the vertical in free fall. rodwarp's step = the protocol's adaptive step "
             f"(safety {STEP_SAFETY:g}, {ITERATIONS} Gauss-Seidel sweeps unless stated, no drive). k_c = IMC stiffness "
             "in rod weights per delta (rodwarp's default 1000; 100 is about DisMech's floor for its gram-scale "
             "rods). Exact rows roll; IMC rows lock the spin. mu = 0.2. Contact ended = the contact impulse stopped "
             f"for {QUIET:g} of the window (contact time: until then; crossed rods stopped inelastically fall on "
             "together without pressing, so their contact ends too); a failure names the step's error.", ""]
    for rk in dict.fromkeys(_rods_key(r) for r in rows):
        sub = [r for r in rows if _rods_key(r) == rk]
        r0 = sub[0]
        lines += [f"## {rk} (l = {r0['length_m'] * 1e3:g} mm, d = {r0['diameter_m'] * 1e3:.3g} mm, "
                  f"g = {r0['gravity_m_s2']:g} m/s^2)", "",
                  "| impact | law, step | " + " | ".join(f"e at {s:g} m/s" for s in speeds)
                  + " | contact time at 1 m/s | notes at 1 m/s |",
                  "|---|---|" + "---|" * len(speeds) + "---|---|"]
        for kind in KINDS:
            for lk in dict.fromkeys(_law_key(r) for r in sub if r["impact"] == kind):
                cells = {r["nominal_speed_m_s"]: r for r in sub if r["impact"] == kind and _law_key(r) == lk}
                one = cells.get(1.0) or next(iter(cells.values()))
                ct = one["contact_time_s"]
                lines.append(f"| {kind} | {lk} | " + " | ".join(_f(cells[s]["e"]) if s in cells else "" for s in speeds)
                             + f" | {'-' if ct is None else f'{ct * 1e3:.3g} ms'} | {one['notes']} |")
        lines.append("")
    lines += ["![e against the impact speed](restitution.png)", "",
              "What it means for the paper's simulator and the stability test: docs/physics.md, \"Restitution\".", ""]
    return "\n".join(lines)


def chart(rows: list[dict], path: Path, title: str) -> None:
    """``restitution.png``: e against the measured impact speed, one panel per impact kind, a colour
    per law and step, a marker per rod configuration."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from rodwarp.rodset.files import save_figure

    laws = list(dict.fromkeys(_law_key(r) for r in rows))
    rods = list(dict.fromkeys(_rods_key(r) for r in rows))
    colors = dict(zip(laws, ("black", "tab:gray", "tab:blue", "tab:cyan", "tab:green", "tab:red", "tab:brown",
                             "tab:orange", "tab:purple", "tab:olive", "tab:pink")))
    markers = dict(zip(rods, ("o", "s", "D", "^", "v", "P")))
    fig = Figure(figsize=(15, 5.2))
    axes = fig.subplots(1, len(KINDS), sharey=True)
    for ax, kind in zip(axes, KINDS):
        for lk in laws:
            for rk in rods:
                pts = sorted((r["impact_speed_m_s"], r["e"]) for r in rows if r["impact"] == kind and _law_key(r) == lk
                             and _rods_key(r) == rk and r["e"] is not None)
                if pts:
                    x, y = zip(*pts)
                    ax.plot(x, y, color=colors.get(lk, "tab:purple"), marker=markers.get(rk, "x"), ms=5, lw=1,
                            alpha=0.85)
        ax.set_xscale("log")
        ax.set_xlim(0.08, 4.5)
        ax.set_title({"flat": "flat drop onto the floor", "end": f"end-first ({TILT_DEG:g} deg) onto the floor",
                      "cross": "crossed rods, relative"}[kind])
        ax.set_xlabel("impact speed v_in (m/s); dashed: the stability test's floor speeds")
        ax.axhline(0.3, color="0.6", lw=0.6, ls=":")
        for v, what in STABILITY_SPEEDS:
            ax.axvline(v, color="0.75", lw=0.8, ls="--", zorder=0)
            ax.text(v, 1.0, what, rotation=90, fontsize=6.5, color="0.45", ha="right", va="top")
        ax.set_ylim(-0.03, 1.03)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("e = v_out / v_in (centroid normal speed)")
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colors.get(lk, "tab:purple"), label=lk) for lk in laws]
    handles += [Line2D([], [], color="0.3", marker=markers.get(rk, "x"), ls="", label=rk) for rk in rods]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=10)
    fig.subplots_adjust(left=0.05, right=0.99, top=0.88, bottom=0.3, wspace=0.06)
    save_figure(fig, path)


def write_outputs(rows: list[dict], out: Path, meta: dict) -> None:
    """``restitution.csv``, ``.md`` and ``.png`` in ``out``, written atomically."""
    from rodwarp.rodset.files import write_text

    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "restitution.csv", to_csv(rows))
    write_text(out / "restitution.md", markdown(rows, meta))
    v = meta["versions"]
    chart(rows, out / "restitution.png", "Coefficient of restitution of rodwarp's contact laws "
          f"({meta['device'].split(' (')[0]}, rodwarp {v['rodwarp']}, warp {v['warp']}; {meta['command']})")


def read_csv(path: Path) -> list[dict]:
    """Rows of a ``restitution.csv`` back as :func:`summarise` makes them (numbers as numbers,
    empty cells as None; a file from before the restitution option: restitution 0)."""
    rows = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            row = {}
            for k in CSV_COLUMNS:
                v = r.get(k, "0" if k == "restitution" else "")
                if v == "":
                    row[k] = None
                elif k in ("impact", "law", "model", "scale", "notes") or (k == "dt_s" and v == "adaptive"):
                    row[k] = v
                elif k in ("iterations", "vertices", "phases"):
                    row[k] = int(float(v))
                else:
                    row[k] = float(v)
            if row["notes"] is None:
                row["notes"] = ""
            # written back as read (a float read and written again would change its text)
            row["_raw"] = {k: r.get(k, "0.0" if k == "restitution" else "") for k in CSV_COLUMNS}
            rows.append(row)
    return rows


def merge_rows(old: list[dict], new: list[dict]) -> list[dict]:
    """``old`` without its restitution-option rows, each configuration's new rows after its
    own (rows keep the plan's order: rod configuration, impact, law)."""
    kept = [r for r in old if not r.get("restitution")]
    out = []
    for rk in dict.fromkeys(_rods_key(r) for r in kept + new):
        for kind in KINDS:
            out += [r for r in kept if _rods_key(r) == rk and r["impact"] == kind]
            out += [r for r in new if _rods_key(r) == rk and r["impact"] == kind]
    return out


def _engine_dirty() -> list[str]:
    """Files of the engine this script runs (rodwarp/sim, kernels) modified in the working tree."""
    import subprocess

    try:
        out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "rodwarp/sim", "kernels"],
                             cwd=ROOT, capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return ["unknown (git did not answer)"]
    return [ln[3:] for ln in out.splitlines() if ln.strip()]


def _merged_from(md: Path) -> str:
    """The generation line of the results a merge keeps (their first 'Generated by' sentence)."""
    try:
        for line in md.read_text().splitlines():
            if line.startswith("Generated by "):
                return line.split(". The engine")[0].split(" (rodwarp")[0]
    except OSError:
        pass
    return "an earlier run"


def _fail(msg: str) -> int:
    print(f"error: {msg}", file=sys.stderr)
    return 2


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit status 2
        print(f"error: {message} (see 'python scripts/restitution.py --help')", file=sys.stderr)
        raise SystemExit(2)


def main(argv=None) -> int:
    ap = _Parser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a small subset, for tests (alpha 100 elastic, 2 speeds)")
    ap.add_argument("--out", default=str(OUT), help="output folder (default benchmarks/results/restitution)")
    ap.add_argument("--only-restitution-option", action="store_true",
                    help="measure only the exact law's restitution option rows (e = 0.5, 0.9; rigid rods) and "
                         "merge them into the folder's restitution.csv (the other rows kept as they are)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    if not a.out.strip():
        return _fail("--out is empty; give a folder")
    if out.exists() and not out.is_dir():
        return _fail(f"--out {a.out} is a file; give a folder")
    sys.path.insert(0, str(ROOT))
    from benchmarks import common

    import warp as wp

    wp.config.quiet = True
    cpu0 = time.process_time()
    only = a.only_restitution_option
    if only and not (out / "restitution.csv").is_file():
        return _fail(f"--only-restitution-option merges into {out / 'restitution.csv'}, which does not exist; run "
                     "without it first")
    rows = run_plan(cases(a.quick, only_restitution=only))
    if only:
        rows = merge_rows(read_csv(out / "restitution.csv"), rows)
    cmd = "python scripts/restitution.py" + (" --quick" if a.quick else "") + (" --only-restitution-option"
                                                                               if only else "")
    if a.out != str(OUT):
        cmd += f" --out {common.command_arg(a.out)}"
    meta = {"command": cmd, "date": common.utc_now(), "versions": common.versions(),
            "device": common.device_name("cpu"), "cpu_s": time.process_time() - cpu0, "engine_dirty": _engine_dirty()}
    if only:
        meta["merged"] = _merged_from(out / "restitution.md")
    write_outputs(rows, out, meta)
    print(f"wrote {out / 'restitution.csv'}, .md and .png ({meta['cpu_s']:.0f} s of CPU)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
