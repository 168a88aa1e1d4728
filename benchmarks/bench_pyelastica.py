"""PyElastica side by side with rodwarp, in the same process: a hanging cantilever and a falling pile.

PyElastica (Cosserat rods, explicit symplectic position Verlet, numba kernels) is an optional
peer: ``pip install -e .[peers]``.  Without it the benchmark is recorded as skipped.

a. Clamped cantilever under gravity (the test material of ``tests/test_mechanics.py``:
   E = 1e9 Pa, rho = 1000 kg/m^3, r = 0.01 m, L = 1 m, Poisson 0.3).
   * Tip sag after settling (gravity, linear velocity damping 40 1/s on both codes, 1 s of
     simulated time) against q L^4 / (8 E I); first bending frequency (no gravity, no damping,
     tip velocity 0.01 (x/L)^2 m/s, 1 s) from the tip's upward zero crossings against
     1.8751^2 / (2 pi) sqrt(E I / (rho A L^4)).
   * Each code gets a grid of settings.  rodwarp: edges x time step (``bending="auto"``: explicit
     below 0.8x its explicit bending bound, implicit above; 4 Gauss-Seidel iterations for the
     sag, 2 for the frequency, as in ``bench_accuracy``).  PyElastica: elements, each with its
     largest stable step: dt = 0.95 x the largest step that survived 3000 steps of the
     undamped, gravity-loaded clamped rod (log bisection, ~6% resolution; PyElastica's step is
     bounded by its shear/rotation mode, dt < ~2 r sqrt(rho / (4/3 G)) / 2, and by h / c).
     Two PyElastica clamps: the standard one (``OneEndFixedBC`` on node 0 and element 0, rod
     starting at the wall) and a *shifted* one where the rod starts h / 2 behind the wall, so
     the clamped (rigid) first element is centred on it; with the standard clamp the rigid
     first element shortens the beam by about h / 2, a first-order error (about -2h / L in
     sag), the shifted clamp makes it second order (the same reason rodwarp's clamp uses a
     short ghost edge).
   * Cost: wall time per simulated second of one rod (rodwarp: K steps timed, repeated;
     PyElastica: the accuracy run itself timed in chunks of steps, median chunk) and per rod in
     a batch of 100 independent cantilevers at the chosen settings.  *Equal accuracy*: for each
     code the cheapest setting of its grid whose |error| is at most the target (2% and 1%); the
     ratio is rodwarp / PyElastica of those costs (< 1: rodwarp cheaper).
b. A pile of 100 steel rods (E = 200 GPa, rho = 7850 kg/m^3, Poisson 0.3, l = 1 m, d = 0.01 m,
   10 vertices = 9 elements) falling onto a floor.  The rods are placed by RSA (seed 1) in a
   1 x 1 x 0.6 m box with floor and four side walls (rod-plane mu = 0.2, rod-rod mu = 0:
   PyElastica has no rod-rod friction) and dropped in rodwarp for 0.2 s, when the pile is
   landing (about 3 contacts per rod, speeds up to ~4 m/s).  That state is handed to both codes,
   which then simulate the same ``T`` (0.005 s quick, 0.02 s full): rodwarp continues with its
   defaults (``RodSolver(model)``, dt = ``default_dt()`` rounded to divide T); PyElastica gets the
   same vertices (rest shape straight, directors parallel-transported along each rod, no twist),
   the same vertex velocities and each element's angular velocity from its tangent's rate, with
   ``RodRodContact`` (penalty k = 1e7 N/m, critical damping of two elements) and
   ``RodPlaneContactWithAnisotropicFriction`` for the five walls (k = 1e7 N/m, critical damping
   of one element, static and kinetic mu 0.2 in all directions), at dt = 0.95 x the largest
   stable step of a free steel rod (bisection as above; measured before: dt <= 1.6e-6 s).
   PyElastica registers contact per rod pair (and per rod-plane pair) in Python; the outcome run
   registers only those that can meet within T (gap at hand-over below reach_i + reach_j,
   reach = 1.5 v_max T + g T^2 + d / 4 per rod; checked at T/2 and T: no other pair
   overlapped), and the cost with all 4950 rod pairs and 500 rod-plane pairs registered (as the
   earlier PyElastica measurement did) is timed on 20 steps per repeat.  Outcome, both codes:
   centroid height, mean vertical velocity, kinetic energy, rod-rod contacts (gap < d/10), deepest rod-rod
   overlap and floor penetration (at vertices, and at element centres where PyElastica's plane
   contact acts) at T, and the RMS difference of the vertices between the two codes against
   their RMS displacement.
"""

from __future__ import annotations

import importlib.metadata
import logging
import math
import time
import warnings

import numpy as np

from benchmarks import common
from benchmarks.common import fmt, log

NAME = "pyelastica"
TITLE = "PyElastica side by side: cantilever at equal accuracy, falling 100-rod pile"

CANT = {"sag_time_s": 1.0, "damping_per_s": 40.0, "freq_time_s": 1.0, "tip_velocity_m_s": 0.01,
        "rodwarp_sag_iterations": 4, "rodwarp_freq_iterations": 2, "poisson": 0.3,
        "pe_stability_steps": 3000, "pe_dt_safety": 0.95}
TARGETS = (0.02, 0.01)
STEEL_PILE = {"n_rods": 100, "length_m": 1.0, "diameter_m": 0.01, "n_vertices": 10, "seed": 1,
              "box_m": (1.0, 1.0, 0.6), "handover_s": 0.2, "floor_mu": 0.2, "rod_rod_mu": 0.0,
              "k_rod_rod_N_per_m": 1e7, "k_plane_N_per_m": 1e7, "slip_velocity_tol": 1e-4}
BATCH = 100


# ----------------------------------------------------------------------------------------------
# PyElastica helpers
# ----------------------------------------------------------------------------------------------

def _import_elastica():
    try:
        import elastica  # noqa: F401
    except Exception as e:  # noqa: BLE001 - ImportError, or numba failing to load
        return None, None, f"{type(e).__name__}: {e}"
    logging.getLogger("elastica").setLevel(logging.WARNING)
    try:
        ver = importlib.metadata.version("pyelastica")
    except importlib.metadata.PackageNotFoundError:
        ver = "unknown"
    return elastica, ver, None


def _sim_class(ea):
    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping, ea.Contact):
        pass

    return Sim


def _pe_steps(ea, sim, dt: float, n: int, t: float = 0.0, chunk: int = 0, sample=None, every: int = 0):
    """n PositionVerlet steps; returns (time, chunk wall times, non-finite flag).  ``sample(t)``
    is called every ``every`` steps (and at the start)."""
    st = ea.PositionVerlet()
    t = np.float64(t)
    dt = np.float64(dt)
    walls = []
    chunk = chunk or n
    done = 0
    if sample is not None:
        sample(float(t))
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        while done < n:
            m = min(chunk, n - done)
            t0 = time.perf_counter()
            if sample is None:
                for _ in range(m):
                    t = st.step(sim, t, dt)
            else:
                for k in range(m):
                    t = st.step(sim, t, dt)
                    if (done + k + 1) % every == 0:
                        sample(float(t))
            walls.append((time.perf_counter() - t0, m))
            done += m
    return float(t), walls


def _chunk_cost(walls) -> dict:
    """Seconds per step from timed chunks: spread over the full-size chunks."""
    full = max(m for _, m in walls)
    per = [w / m for w, m in walls if m == full] or [w / m for w, m in walls]
    return common.spread(per)


def _test_props():
    from rodwarp.testing.scenes import TEST_DENSITY, TEST_LENGTH, TEST_RADIUS, TEST_YOUNG

    return TEST_YOUNG, TEST_DENSITY, TEST_RADIUS, TEST_LENGTH


def _pe_cantilever(ea, n: int, dt: float, *, shift: bool, gravity: bool, damping: float, tip_velocity: float = 0.0,
                   copies: int = 1):
    """PyElastica simulator of ``copies`` clamped cantilevers of n elements (test material)."""
    E, rho, r, L = _test_props()
    sim = _sim_class(ea)()
    if shift:
        h = L / (n - 0.5)
        x0, length = -0.5 * h, L + 0.5 * h
    else:
        x0, length = 0.0, L
    rods = []
    for k in range(copies):
        off = np.array([0.0, 0.05 * (k % 10), 0.05 * (k // 10)])
        rod = ea.CosseratRod.straight_rod(n, np.array([x0, 0.0, 0.0]) + off, np.array([1.0, 0.0, 0.0]),
                                          np.array([0.0, 0.0, 1.0]), length, r, rho, youngs_modulus=E,
                                          shear_modulus=E / (2 * (1 + CANT["poisson"])))
        sim.append(rod)
        sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
        if gravity:
            sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array([0.0, 0.0, -9.81]))
        if damping:
            sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=damping, time_step=dt)
        rods.append(rod)
    sim.finalize()
    for rod in rods:
        if tip_velocity:
            x = rod.position_collection[0].clip(0.0, None)
            rod.velocity_collection[2] = tip_velocity * (x / x.max()) ** 2
    return sim, rods


def _pe_finite(rods) -> bool:
    return all(np.isfinite(r.velocity_collection).all() and np.abs(r.velocity_collection).max() < 10.0 for r in rods)


def _pe_survives(ea, build, dt: float, steps: int) -> bool:
    sim, rods = build(dt)
    rng = np.random.default_rng(0)
    for r in rods:
        r.velocity_collection[:] += 1e-4 * rng.standard_normal(r.velocity_collection.shape)
    st = ea.PositionVerlet()
    t = np.float64(0.0)
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        for k in range(steps):
            t = st.step(sim, t, np.float64(dt))
            if k % 500 == 499 and not _pe_finite(rods):
                return False
    return _pe_finite(rods)


def _pe_stable_dt(ea, build, lo: float, hi: float, steps: int, iters: int = 6) -> dict:
    """Largest step that survives ``steps`` steps, by bisection in log dt between lo (assumed
    stable) and hi (assumed unstable); both ends are checked."""
    tried = []
    if not _pe_survives(ea, build, lo, steps):
        return {"stable_dt_s": None, "tried": [(lo, False)]}
    tried.append((lo, True))
    while _pe_survives(ea, build, hi, steps):
        tried.append((hi, True))
        lo, hi = hi, hi * 2.0
    tried.append((hi, False))
    for _ in range(iters):
        mid = math.sqrt(lo * hi)
        ok = _pe_survives(ea, build, mid, steps)
        tried.append((mid, ok))
        lo, hi = (mid, hi) if ok else (lo, mid)
    return {"stable_dt_s": lo, "first_unstable_dt_s": hi, "tried": [[float(a), bool(b)] for a, b in tried]}


# ----------------------------------------------------------------------------------------------
# a. cantilever
# ----------------------------------------------------------------------------------------------

def _exact():
    from rodwarp.testing.scenes import cantilever_frequency, cantilever_sag

    return cantilever_sag(), cantilever_frequency()


def _pe_setting(ea, n: int, shift: bool, quick: bool) -> dict:
    """One PyElastica discretisation: its stable step, tip sag and first frequency, and cost."""
    from benchmarks.bench_accuracy import _oscillation

    sag0, f0 = _exact()
    stab = _pe_stable_dt(ea, lambda dt: _pe_cantilever(ea, n, dt, shift=shift, gravity=True, damping=0.0),
                         1e-6, 3e-5, CANT["pe_stability_steps"])
    row = {"code": "pyelastica", "clamp": "shifted" if shift else "standard", "n_elements": n, "stability": stab}
    if stab["stable_dt_s"] is None:
        row["failure"] = "no stable step found above 1e-6 s"
        return row
    dt = CANT["pe_dt_safety"] * stab["stable_dt_s"]
    for attempt in range(3):
        # tip sag
        sim, rods = _pe_cantilever(ea, n, dt, shift=shift, gravity=True, damping=CANT["damping_per_s"])
        nsteps = int(round(CANT["sag_time_s"] / dt))
        t0 = time.perf_counter()
        _, walls = _pe_steps(ea, sim, dt, nsteps, chunk=max(nsteps // 8, 1))
        sag_wall = time.perf_counter() - t0
        if not _pe_finite(rods):
            dt /= 1.15
            continue
        sag = -float(rods[0].position_collection[2, -1])
        # frequency: tip z sampled every ~1e-4 s
        sim, rods = _pe_cantilever(ea, n, dt, shift=shift, gravity=False, damping=0.0,
                                   tip_velocity=CANT["tip_velocity_m_s"])
        ts, zs = [], []
        rod = rods[0]

        def sample(t):
            ts.append(t)
            zs.append(float(rod.position_collection[2, -1]))

        every = max(1, int(round(1e-4 / dt)))
        nf = int(round(CANT["freq_time_s"] / dt))
        _, fwalls = _pe_steps(ea, sim, dt, nf, chunk=max(nf // 8, 1), sample=sample, every=every)
        if not _pe_finite(rods):
            dt /= 1.15
            continue
        f, zeta = _oscillation(ts, zs)
        cost = _chunk_cost(walls)
        row.update({"dt_s": dt, "dt_retries": attempt, "steps_per_sim_s": 1.0 / dt,
                    "sag_m": sag, "sag_rel_error": (sag - sag0) / sag0,
                    "frequency_hz": f, "frequency_rel_error": None if f is None else (f - f0) / f0,
                    "damping_ratio": zeta, "sag_run_wall_s": sag_wall,
                    "s_per_step": cost, "cost_s_per_sim_s": common.scale_spread(cost, 1.0 / dt),
                    "freq_cost_s_per_sim_s": common.scale_spread(_chunk_cost(fwalls), 1.0 / dt)})
        return row
    row["failure"] = "blew up in the long runs even at dt / 1.15^3"
    return row


def _rw_setting(n: int, dt: float, kind: str, device: str, repeats: int) -> dict:
    """One rodwarp (edges, dt) setting: sag or frequency error and cost per simulated second."""
    from benchmarks.bench_accuracy import _cantilever_model, _oscillation, _run_catching, _step_cost
    from rodwarp.sim.solver import RodSolver, run

    sag0, f0 = _exact()
    row = {"code": "rodwarp", "n_edges": n, "dt_s": dt, "kind": kind}
    if kind == "sag":
        model = _cantilever_model(n, gravity=(0, 0, -9.81), damping=CANT["damping_per_s"], device=device)
        solver = RodSolver(model, iterations=CANT["rodwarp_sag_iterations"], allow_unstable=True)
        st, err = _run_catching(lambda: run(solver, model.state(), CANT["sag_time_s"], dt))
        row["failure"] = err
        if err is None:
            sag = -float(st.positions()[-1, 2])
            row.update({"sag_m": sag, "rel_error": (sag - sag0) / sag0})
    else:
        model = _cantilever_model(n, gravity=(0, 0, 0), damping=0.0, tip_velocity=CANT["tip_velocity_m_s"],
                                  device=device)
        solver = RodSolver(model, iterations=CANT["rodwarp_freq_iterations"], allow_unstable=True)
        ts, zs = [], []
        _, err = _run_catching(lambda: run(solver, model.state(), CANT["freq_time_s"], dt,
                                           callback=lambda s, i: (zs.append(float(s.x.numpy()[-1, 2])),
                                                                  ts.append(s.time))))
        row["failure"] = err
        if err is None:
            f, zeta = _oscillation(ts, zs)
            row.update({"frequency_hz": f, "rel_error": None if f is None else (f - f0) / f0, "damping_ratio": zeta})
    row["theta"] = solver.theta_for(dt)
    row["bending"] = "explicit" if row["theta"] == 0.0 else "implicit"
    if row["failure"] is None:
        cost = _step_cost(model, solver, model.state(), dt, 50, repeats, device)
        row["s_per_step"] = cost
        row["cost_s_per_sim_s"] = common.scale_spread(cost, 1.0 / dt)
    return row


def _cheapest(rows, err_key: str, cost_key: str, tol: float):
    ok = [r for r in rows if r.get(err_key) is not None and abs(r[err_key]) <= tol
          and (r.get(cost_key) or {}).get("median") is not None]
    return min(ok, key=lambda r: r[cost_key]["median"]) if ok else None


def _batch_cost(ea, pe_row, rw_row, device: str, repeats: int) -> dict:
    """Per-rod cost per simulated second for BATCH independent cantilevers, both codes (sag setting)."""
    from benchmarks.bench_accuracy import _cantilever_model, _step_cost
    from rodwarp.sim.solver import RodSolver

    out = {"rods": BATCH}
    if rw_row is not None:
        dt = rw_row["dt_s"]
        bm = _cantilever_model(rw_row["n_edges"], gravity=(0, 0, -9.81), damping=CANT["damping_per_s"], copies=BATCH,
                               device=device)
        bs = RodSolver(bm, iterations=CANT["rodwarp_sag_iterations"], allow_unstable=True)
        c = _step_cost(bm, bs, bm.state(), dt, 10, repeats, device)
        out["rodwarp"] = {"n_edges": rw_row["n_edges"], "dt_s": dt,
                          "cost_per_rod_s_per_sim_s": common.scale_spread(c, 1.0 / (dt * BATCH))}
    if pe_row is not None:
        dt = pe_row["dt_s"]
        sim, rods = _pe_cantilever(ea, pe_row["n_elements"], dt, shift=pe_row["clamp"] == "shifted", gravity=True,
                                   damping=CANT["damping_per_s"], copies=BATCH)
        _pe_steps(ea, sim, dt, 20)  # warm-up
        _, walls = _pe_steps(ea, sim, dt, 100 * repeats, chunk=100)
        c = _chunk_cost(walls)
        out["pyelastica"] = {"n_elements": pe_row["n_elements"], "clamp": pe_row["clamp"], "dt_s": dt,
                             "cost_per_rod_s_per_sim_s": common.scale_spread(c, 1.0 / (dt * BATCH))}
    if "rodwarp" in out and "pyelastica" in out:
        out["rodwarp_over_pyelastica"] = (out["rodwarp"]["cost_per_rod_s_per_sim_s"]["median"]
                                          / out["pyelastica"]["cost_per_rod_s_per_sim_s"]["median"])
    return out


def _cantilever(ea, quick: bool, device: str) -> dict:
    repeats = common.n_repeats(quick)
    sag0, f0 = _exact()
    if quick:
        rw_edges, sag_dts, freq_dts = [4, 6, 9, 16], [1e-3, 1e-2, 3e-2], [1e-3, 3e-3, 1e-2]
        pe_std, pe_shift = [9, 32, 128], [4, 6, 9]
    else:
        rw_edges, sag_dts, freq_dts = [4, 6, 9, 16, 32], [1e-3, 3e-3, 1e-2, 3e-2], [5e-4, 1e-3, 2e-3, 3e-3, 5e-3, 1e-2]
        pe_std, pe_shift = [9, 16, 32, 64, 128, 200], [4, 6, 9, 16]
    rw_sag, rw_freq = [], []
    for n in rw_edges:
        for dt in sag_dts:
            rw_sag.append(_rw_setting(n, dt, "sag", device, repeats))
        for dt in freq_dts:
            rw_freq.append(_rw_setting(n, dt, "frequency", device, repeats))
        log(f"rodwarp cantilever {n} edges: sag err " + ", ".join(
            f"{fmt(r['dt_s'])}: {fmt(r.get('rel_error'))}" for r in rw_sag if r["n_edges"] == n) + "; f err " + ", ".join(
            f"{fmt(r['dt_s'])}: {fmt(r.get('rel_error'))}" for r in rw_freq if r["n_edges"] == n))
    pe_rows = []
    for shift, ns in ((False, pe_std), (True, pe_shift)):
        for n in ns:
            r = _pe_setting(ea, n, shift, quick)
            pe_rows.append(r)
            log(f"PyElastica cantilever {r['clamp']} clamp, {n} elements: dt {fmt(r.get('dt_s'))} s, sag err "
                f"{fmt(r.get('sag_rel_error'))}, f err {fmt(r.get('frequency_rel_error'))}, "
                f"{fmt((r.get('cost_s_per_sim_s') or {}).get('median'))} s per simulated s")
    equal = {}
    for qty, rw_rows, pe_err, pe_cost in (("sag", rw_sag, "sag_rel_error", "cost_s_per_sim_s"),
                                          ("frequency", rw_freq, "frequency_rel_error", "freq_cost_s_per_sim_s")):
        for tol in TARGETS:
            rw = _cheapest(rw_rows, "rel_error", "cost_s_per_sim_s", tol)
            pe = _cheapest(pe_rows, pe_err, pe_cost, tol)
            pe_std_best = _cheapest([r for r in pe_rows if r["clamp"] == "standard"], pe_err, pe_cost, tol)
            e = {"target": tol,
                 "rodwarp": None if rw is None else {"n_edges": rw["n_edges"], "dt_s": rw["dt_s"],
                                                     "bending": rw["bending"], "rel_error": rw["rel_error"],
                                                     "cost_s_per_sim_s": rw["cost_s_per_sim_s"]},
                 "pyelastica": None if pe is None else {"n_elements": pe["n_elements"], "clamp": pe["clamp"],
                                                        "dt_s": pe["dt_s"], "rel_error": pe[pe_err],
                                                        "cost_s_per_sim_s": pe[pe_cost]},
                 "pyelastica_standard_clamp": None if pe_std_best is None else {
                     "n_elements": pe_std_best["n_elements"], "dt_s": pe_std_best["dt_s"],
                     "rel_error": pe_std_best[pe_err], "cost_s_per_sim_s": pe_std_best[pe_cost]}}
            if rw and pe:
                e["rodwarp_over_pyelastica"] = rw["cost_s_per_sim_s"]["median"] / pe[pe_cost]["median"]
            if rw and pe_std_best:
                e["rodwarp_over_pyelastica_standard_clamp"] = (rw["cost_s_per_sim_s"]["median"]
                                                               / pe_std_best[pe_cost]["median"])
            equal[f"{qty}_{tol:g}"] = e
    e2 = equal["sag_0.02"]
    rw_pick = next((r for r in rw_sag if e2["rodwarp"] and r["n_edges"] == e2["rodwarp"]["n_edges"]
                    and r["dt_s"] == e2["rodwarp"]["dt_s"]), None)
    pe_pick = next((r for r in pe_rows if e2["pyelastica"] and r["n_elements"] == e2["pyelastica"]["n_elements"]
                    and r["clamp"] == e2["pyelastica"]["clamp"]), None)
    batch = _batch_cost(ea, pe_pick, rw_pick, device, repeats)
    log(f"batch of {BATCH} cantilevers, per rod: rodwarp/PyElastica = {fmt(batch.get('rodwarp_over_pyelastica'))}")
    return {"exact_sag_m": sag0, "exact_frequency_hz": f0, "protocol": CANT,
            "rodwarp_sag": rw_sag, "rodwarp_frequency": rw_freq, "pyelastica": pe_rows,
            "equal_accuracy": equal, "batch": batch}


# ----------------------------------------------------------------------------------------------
# b. falling pile
# ----------------------------------------------------------------------------------------------

def _rod_gaps(pos: np.ndarray, radius: float, chunk: int = 600):
    """Surface gap of every rod pair (closest segment pair): (i, j, gap) with i < j."""
    from rodwarp.rodset import segment_distance

    N = pos.shape[0]
    a, b = pos[:, :-1], pos[:, 1:]
    iu, ju = np.triu_indices(N, 1)
    gap = np.empty(len(iu))
    for s in range(0, len(iu), chunk):
        i, j = iu[s:s + chunk], ju[s:s + chunk]
        d = segment_distance(a[i][:, :, None], b[i][:, :, None], a[j][:, None], b[j][:, None])
        gap[s:s + chunk] = d.reshape(len(i), -1).min(axis=1) - 2 * radius
    return iu, ju, gap


def _frames(pos: np.ndarray):
    """Per-element directors (3, 3, n) of a polyline (V, 3): d3 the tangent, d1 parallel-transported
    from the first element (no twist, as rodwarp's rods have none), d2 = d3 x d1."""
    t = np.diff(pos, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    n = len(t)
    ref = np.array([0.0, 0.0, 1.0]) if abs(t[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    d1 = ref - (ref @ t[0]) * t[0]
    d1 /= np.linalg.norm(d1)
    Q = np.zeros((3, 3, n))
    for e in range(n):
        if e:
            a, b = t[e - 1], t[e]
            k = np.cross(a, b)
            c = float(a @ b)
            d1 = d1 * c + np.cross(k, d1) + k * (k @ d1) / (1.0 + c)
            d1 -= (d1 @ b) * b
            d1 /= np.linalg.norm(d1)
        Q[0, :, e] = d1
        Q[1, :, e] = np.cross(t[e], d1)
        Q[2, :, e] = t[e]
    return Q


def _plane_gaps(pos: np.ndarray, planes, radius: float) -> np.ndarray:
    """(N, P) smallest surface gap of each rod to each plane {x : n . x >= offset}."""
    return np.stack([(pos @ pl.normal).min(axis=1) - pl.offset - radius for pl in planes], axis=1)


def _outcome(pos, vel, mass, radius, pos0, planes, iu_ju_gap=None) -> dict:
    """Comparable quantities of a pile state (positions (N, V, 3))."""
    iu, ju, gap = iu_ju_gap if iu_ju_gap is not None else _rod_gaps(pos, radius)
    m = mass.reshape(pos.shape[:2])
    M = m.sum()
    z = pos[..., 2]
    contact = gap < 0.2 * radius  # d / 10
    pg = _plane_gaps(pos, planes, radius)
    floor = [k for k, pl in enumerate(planes) if pl.name == "floor"][0]
    disp = np.linalg.norm(pos - pos0, axis=-1)
    mid = 0.5 * (pos[:, 1:] + pos[:, :-1])  # element centres: where PyElastica's plane contact acts
    mid_gap = (mid @ planes[floor].normal).min() - planes[floor].offset - radius
    return {"centroid_height_m": float((m * z).sum() / M),
            "mean_vertical_velocity_m_s": float((m * vel[..., 2]).sum() / M),
            "kinetic_energy_J": float(0.5 * (m * (vel ** 2).sum(-1)).sum()),
            "rod_rod_contacts": int(contact.sum()), "Z": float(2 * contact.sum() / pos.shape[0]),
            "max_rod_overlap_over_d": float(max(0.0, -gap.min()) / (2 * radius)),
            "max_floor_penetration_over_d": float(max(0.0, -pg[:, floor].min()) / (2 * radius)),
            "max_floor_penetration_element_centres_over_d": float(max(0.0, -mid_gap) / (2 * radius)),
            "max_wall_penetration_over_d": float(max(0.0, -pg.min()) / (2 * radius)),
            "rods_on_floor": int((pg[:, floor] < 0.2 * radius).sum()),
            "rms_displacement_m": float(np.sqrt((disp ** 2).mean())),
            "max_speed_m_s": float(np.linalg.norm(vel, axis=-1).max())}


def _pe_pile_sim(ea, X, U, planes, pairs, plane_rods, dt: float):
    """PyElastica simulator of the hand-over state (positions X and velocities U, (N, V, 3)) with
    rod-rod contact on ``pairs`` and contact with plane p for the rods in ``plane_rods[p]``."""
    p = STEEL_PILE
    from rodwarp.sim.model import STEEL

    r = 0.5 * p["diameter_m"]
    E, rho = STEEL.young, STEEL.density
    h = p["length_m"] / (p["n_vertices"] - 1)
    m_el = rho * math.pi * r * r * h
    k_rr, k_pl = p["k_rod_rod_N_per_m"], p["k_plane_N_per_m"]
    nu_rr = 2 * math.sqrt(k_rr * 0.5 * m_el)  # critical for two elements (reduced mass m/2)
    nu_pl = 2 * math.sqrt(k_pl * m_el)
    sim = _sim_class(ea)()
    rods = []
    for k in range(X.shape[0]):
        Q = _frames(X[k])
        u = X[k, -1] - X[k, 0]
        rod = ea.CosseratRod.straight_rod(p["n_vertices"] - 1, X[k, 0].copy(), u / np.linalg.norm(u), Q[0, :, 0].copy(),
                                          float(np.linalg.norm(np.diff(X[k], axis=0), axis=1).sum()), r, rho,
                                          youngs_modulus=E, shear_modulus=E / (2 * (1 + STEEL.poisson)),
                                          position=X[k].T.copy(), directors=Q)
        sim.append(rod)
        sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array([0.0, 0.0, -9.81]))
        rods.append(rod)
    mu = np.full(3, p["floor_mu"])
    for q, pl in enumerate(planes):
        plane = ea.Plane(plane_origin=np.asarray(pl.normal) * pl.offset, plane_normal=np.asarray(pl.normal, float))
        sim.append(plane)
        for k in plane_rods[q]:
            sim.detect_contact_between(rods[k], plane).using(
                ea.RodPlaneContactWithAnisotropicFriction, k=k_pl, nu=nu_pl, slip_velocity_tol=p["slip_velocity_tol"],
                static_mu_array=mu.copy(), kinetic_mu_array=mu.copy())
    for i, j in pairs:
        sim.detect_contact_between(rods[i], rods[j]).using(ea.RodRodContact, k=k_rr, nu=nu_rr)
    t0 = time.perf_counter()
    sim.finalize()
    fin = time.perf_counter() - t0
    for k, rod in enumerate(rods):
        rod.velocity_collection[:] = U[k].T
        t = np.diff(X[k], axis=0)
        ln = np.linalg.norm(t, axis=1)[:, None]
        w = np.cross(t / ln, np.diff(U[k], axis=0) / ln)  # angular velocity of each element (no spin)
        for e in range(rod.n_elems):
            rod.omega_collection[:, e] = rod.director_collection[:, :, e] @ w[e]
    return sim, rods, fin, {"nu_rod_rod": nu_rr, "nu_plane": nu_pl, "element_mass_kg": m_el}


def _pe_state(rods):
    return (np.stack([r.position_collection.T.copy() for r in rods]),
            np.stack([r.velocity_collection.T.copy() for r in rods]))


def _pile(ea, quick: bool, device: str) -> dict:
    from rodwarp.sim.builder import ModelBuilder
    from rodwarp.sim.model import STEEL
    from rodwarp.experiments import random_packing
    from rodwarp.sim.solver import RodSolver

    p = STEEL_PILE
    repeats = common.n_repeats(quick)
    T = 0.005 if quick else 0.02
    N, V, r = p["n_rods"], p["n_vertices"], 0.5 * p["diameter_m"]
    box = np.array(p["box_m"], float)
    # 1. the falling pile, simulated by rodwarp up to the hand-over time
    rods = random_packing(N, p["length_m"], p["diameter_m"], box, seed=p["seed"], device=device, n_vertices=V)
    builder = ModelBuilder(rods, STEEL, gravity=(0.0, 0.0, -9.81), mu=p["rod_rod_mu"], device=device)
    builder.add_box(np.zeros(3), box, walls=("floor", "x-", "x+", "y-", "y+"), mu=p["floor_mu"])
    model = builder.finalize()
    planes = list(model.planes)
    solver = RodSolver(model)
    ddt = solver.default_dt()
    a = model.state()
    b = common.new_state_like(model, a)
    a, b, _ = common.advance(solver, a, b, ddt, int(round(p["handover_s"] / ddt)))
    mass = model.mass_np.reshape(N, V)
    X = a.positions().reshape(N, V, 3)
    U = a.velocities().reshape(N, V, 3)
    iu, ju, gap0 = _rod_gaps(X, r)
    handover = _outcome(X, U, mass, r, X, planes, (iu, ju, gap0))
    handover.update({"time_s": float(a.time)})
    log(f"pile hand-over at t = {a.time:.3f} s: Z = {handover['Z']:.2f}, centroid {handover['centroid_height_m']:.3f} m, "
        f"max speed {handover['max_speed_m_s']:.2f} m/s, {handover['rods_on_floor']} rods on the floor")

    # 2. rodwarp continues from its own state for T (same model, dt = default rounded to divide T)
    nrw = int(math.ceil(T / ddt))
    rdt = T / nrw
    snap = common.new_state_like(model, a)
    snap_points = common.copy_contacts(solver)
    x = common.new_state_like(model, snap)
    y = common.new_state_like(model, snap)
    x, y, info = common.advance(solver, x, y, rdt, nrw)
    rw_pos, rw_vel = x.positions().reshape(N, V, 3), x.velocities().reshape(N, V, 3)
    rw_out = _outcome(rw_pos, rw_vel, mass, r, X, planes)
    k_time = max(nrw, 30)
    x = common.new_state_like(model, snap)
    y = common.new_state_like(model, snap)

    def restore():
        x.copy_from(snap)
        common.restore_contacts(solver, snap_points)

    def go():
        common.advance(solver, x, y, rdt, k_time)

    rw_step = common.scale_spread(common.time_repeats(go, repeats, setup=restore, device=device, warmup=True),
                                  1.0 / k_time)
    rw_cost = common.scale_spread(rw_step, 1.0 / rdt)
    log(f"rodwarp pile: dt {rdt:.3g} s, {fmt(rw_step['median'] * 1e3)} ms/step, "
        f"{fmt(rw_cost['median'])} s per simulated s; Z {rw_out['Z']:.2f}")

    # 3. PyElastica: stable step of one free steel rod, then the same state for T
    stab = _pe_stable_dt(ea, lambda dt: _pe_free_steel(ea, dt), 5e-7, 4e-6, 5000)
    pdt = CANT["pe_dt_safety"] * stab["stable_dt_s"]
    n_pe = int(math.ceil(T / pdt))
    pdt = T / n_pe
    # contacts that can occur within T: rod pairs and rod-plane pairs within reach
    vmax = np.linalg.norm(U, axis=-1).max(axis=1)
    reach = 1.5 * vmax * T + 9.81 * T * T + 0.25 * p["diameter_m"]
    keep = gap0 < reach[iu] + reach[ju]
    pairs = list(zip(iu[keep].tolist(), ju[keep].tolist()))
    pg0 = _plane_gaps(X, planes, r)
    plane_keep = pg0 < reach[:, None]
    plane_rods = [np.flatnonzero(plane_keep[:, q]).tolist() for q in range(len(planes))]
    # warm-up: compile the contact kernels on a 2-rod scene
    wsim, _, _, _ = _pe_pile_sim(ea, X[:2], U[:2], planes, [(0, 1)], [[0, 1]] * len(planes), pdt)
    _pe_steps(ea, wsim, pdt, 5)
    sim, pe_rods, fin, pe_params = _pe_pile_sim(ea, X, U, planes, pairs, plane_rods, pdt)
    n_plane = int(plane_keep.sum())
    log(f"PyElastica pile: dt {pdt:.3g} s (largest stable {stab['stable_dt_s']:.3g} s), {len(pairs)} of {len(iu)} rod "
        f"pairs and {n_plane} of {plane_keep.size} rod-plane pairs registered, finalize {fin:.2f} s, {n_pe} steps to "
        f"T = {T} s")
    half = n_pe // 2
    t_pe, walls1 = _pe_steps(ea, sim, pdt, half, chunk=500)
    mid_pos, _ = _pe_state(pe_rods)
    t_pe, walls2 = _pe_steps(ea, sim, pdt, n_pe - half, t=t_pe, chunk=500)
    pe_pos, pe_vel = _pe_state(pe_rods)
    finite = bool(np.isfinite(pe_pos).all() and np.isfinite(pe_vel).all())
    pe_step = _chunk_cost(walls1 + walls2)
    pe_cost = common.scale_spread(pe_step, 1.0 / pdt)
    problems = []
    validity = {}
    pe_out = None
    if finite:
        pe_out = _outcome(pe_pos, pe_vel, mass, r, X, planes)
        for label, pos in (("half", mid_pos), ("end", pe_pos)):
            _, _, g = _rod_gaps(pos, r)
            pg = _plane_gaps(pos, planes, r)
            gr = float(g[~keep].min()) if (~keep).any() else None
            gp = float(pg[~plane_keep].min()) if (~plane_keep).any() else None
            validity[label] = {"min_gap_unregistered_rod_pairs_m": gr, "min_gap_unregistered_rod_planes_m": gp}
            for what, gmin in (("rod pair", gr), ("rod-plane pair", gp)):
                if gmin is not None and gmin < 0.0:
                    problems.append(f"pile: an unregistered PyElastica {what} overlapped at the {label} of the run "
                                    f"(gap {gmin:.3g} m): the pruned contact list was too short")
    else:
        problems.append("pile: PyElastica produced non-finite positions")
    diff = float(np.sqrt(((pe_pos - rw_pos) ** 2).sum(-1).mean())) if finite else None
    log(f"PyElastica pile: {fmt(pe_step['median'] * 1e3)} ms/step, {fmt(pe_cost['median'])} s per simulated s; "
        + (f"Z {pe_out['Z']:.2f}, RMS difference to rodwarp {diff * 1e3:.3g} mm" if pe_out else "non-finite"))

    # 4. every pair and every rod-plane pair registered (as measured before): finalize and a few steps
    all_pairs = list(zip(iu.tolist(), ju.tolist()))
    sim_all, _, fin_all, _ = _pe_pile_sim(ea, X, U, planes, all_pairs, [list(range(N))] * len(planes), pdt)
    _pe_steps(ea, sim_all, pdt, 3)
    _, walls_all = _pe_steps(ea, sim_all, pdt, 20 * repeats, chunk=20)
    all_step = _chunk_cost(walls_all)
    all_cost = common.scale_spread(all_step, 1.0 / pdt)
    log(f"PyElastica pile, all {len(all_pairs)} pairs and {N * len(planes)} rod-plane pairs: finalize {fin_all:.2f} s, "
        f"{fmt(all_step['median'] * 1e3)} ms/step")
    return {
        "simulated_time_s": T,
        "settings": dict(STEEL_PILE, **{"rodwarp_solver": "RodSolver(model) defaults", "pyelastica_contact": pe_params,
                                        "planes": [pl.name for pl in planes]}),
        "handover": handover,
        "rodwarp": {"dt_s": rdt, "default_dt_s": ddt, "steps": nrw, "timed_steps": k_time, "s_per_step": rw_step,
                    "cost_s_per_sim_s": rw_cost, "outcome": rw_out, "contacts_last_step": int(info.n_contacts)},
        "pyelastica": {"dt_s": pdt, "stability": stab, "steps": n_pe, "pairs_registered": len(pairs),
                       "pairs_total": len(iu), "rod_planes_registered": n_plane, "rod_planes_total": int(plane_keep.size),
                       "finalize_s": fin, "s_per_step": pe_step, "cost_s_per_sim_s": pe_cost,
                       "outcome": pe_out, "contact_list_validity": validity, "finite": finite},
        "pyelastica_all_pairs": {"pairs": len(all_pairs), "rod_planes": N * len(planes), "finalize_s": fin_all,
                                 "s_per_step": all_step, "cost_s_per_sim_s": all_cost, "timed_steps": 20 * repeats},
        "rms_difference_m": diff,
        "rodwarp_over_pyelastica": rw_cost["median"] / pe_cost["median"] if pe_cost["median"] else None,
        "rodwarp_over_pyelastica_all_pairs": rw_cost["median"] / all_cost["median"] if all_cost["median"] else None,
        "problems": problems,
    }


def _pe_free_steel(ea, dt: float):
    """One free steel rod (9 elements, d = 0.01 m, l = 1 m) under gravity: the stability probe of the pile."""
    from rodwarp.sim.model import STEEL

    p = STEEL_PILE
    sim = _sim_class(ea)()
    rod = ea.CosseratRod.straight_rod(p["n_vertices"] - 1, np.zeros(3), np.array([1.0, 0.0, 0.0]),
                                      np.array([0.0, 0.0, 1.0]), p["length_m"], 0.5 * p["diameter_m"], STEEL.density,
                                      youngs_modulus=STEEL.young, shear_modulus=STEEL.young / (2 * (1 + STEEL.poisson)))
    sim.append(rod)
    sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array([0.0, 0.0, -9.81]))
    sim.finalize()
    return sim, [rod]


# ----------------------------------------------------------------------------------------------
# entry points
# ----------------------------------------------------------------------------------------------

def run(quick: bool, device: str) -> dict:
    ea, ver, why = _import_elastica()
    if ea is None:
        log(f"pyelastica not importable ({why}): recorded as skipped")
        return {"title": TITLE, "skipped": True,
                "reason": f"pyelastica is not installed or does not import ({why}); pip install -e .[peers]",
                "problems": []}
    from rodwarp import _warp

    _warp.init()
    out = {"title": TITLE, "skipped": False, "pyelastica_version": ver,
           "numba_version": _dist_version("numba")}
    problems = []
    try:
        out["cantilever"] = _cantilever(ea, quick, device)
    except Exception as e:  # noqa: BLE001 - record why PyElastica could not run this piece
        import traceback

        traceback.print_exc()
        out["cantilever"] = {"failure": f"{type(e).__name__}: {e}"}
        problems.append(f"cantilever could not run: {type(e).__name__}: {e}")
    try:
        out["pile"] = _pile(ea, quick, device)
        problems += out["pile"].pop("problems", [])
    except Exception as e:  # noqa: BLE001
        import traceback

        traceback.print_exc()
        out["pile"] = {"failure": f"{type(e).__name__}: {e}"}
        problems.append(f"pile could not run: {type(e).__name__}: {e}")
    out["problems"] = problems
    return out


def _dist_version(name: str):
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def _cost_txt(c) -> str:
    return common.fmt_spread(c, 1.0, "s") if c else "—"


def summary(rec: dict) -> list[dict]:
    if rec.get("skipped"):
        return [{"benchmark": "PyElastica peer", "rodwarp": "—", "peer": f"skipped: {rec.get('reason')}",
                 "ratio": None}]
    rows = []
    c = rec.get("cantilever") or {}
    if "failure" in c:
        rows.append({"benchmark": "cantilever vs PyElastica", "rodwarp": "—", "peer": f"failed: {c['failure']}",
                     "ratio": None})
    for key, e in (c.get("equal_accuracy") or {}).items():
        qty = "tip sag" if key.startswith("sag") else "first frequency"
        rw, pe = e["rodwarp"], e["pyelastica"]
        rows.append({
            "benchmark": (f"cantilever {qty}, |error| <= {e['target'] * 100:g}%: wall s per simulated s, one rod "
                          f"(ratio rodwarp / PyElastica)"),
            "rodwarp": ("none in grid" if rw is None else
                        f"{rw['n_edges']} edges, dt {fmt(rw['dt_s'])} s ({rw['bending']}): error "
                        f"{100 * rw['rel_error']:.2f}%, {_cost_txt(rw['cost_s_per_sim_s'])}"),
            "peer": ("none in grid" if pe is None else
                     f"PyElastica {pe['n_elements']} elements, {pe['clamp']} clamp, dt {fmt(pe['dt_s'])} s: error "
                     f"{100 * pe['rel_error']:.2f}%, {_cost_txt(pe['cost_s_per_sim_s'])}"
                     + ("" if not e.get("pyelastica_standard_clamp") or e["pyelastica_standard_clamp"]["n_elements"]
                        == pe["n_elements"] and pe["clamp"] == "standard" else
                        f"; standard clamp: {e['pyelastica_standard_clamp']['n_elements']} elements, "
                        f"{_cost_txt(e['pyelastica_standard_clamp']['cost_s_per_sim_s'])}")),
            "ratio": e.get("rodwarp_over_pyelastica")})
    b = c.get("batch") or {}
    if "rodwarp" in b and "pyelastica" in b:
        rows.append({"benchmark": f"cantilever sag at 2%, batch of {b['rods']} rods: wall s per simulated s per rod "
                                  "(ratio rodwarp / PyElastica)",
                     "rodwarp": f"{b['rodwarp']['n_edges']} edges: {_cost_txt(b['rodwarp']['cost_per_rod_s_per_sim_s'])}",
                     "peer": (f"{b['pyelastica']['n_elements']} elements: "
                              f"{_cost_txt(b['pyelastica']['cost_per_rod_s_per_sim_s'])}"),
                     "ratio": b.get("rodwarp_over_pyelastica")})
    p = rec.get("pile") or {}
    if "failure" in p:
        rows.append({"benchmark": "falling pile vs PyElastica", "rodwarp": "—", "peer": f"failed: {p['failure']}",
                     "ratio": None})
    elif p:
        rw, pe, pa = p["rodwarp"], p["pyelastica"], p["pyelastica_all_pairs"]
        rows.append({
            "benchmark": (f"falling pile, 100 steel rods, {p['simulated_time_s']} s from hand-over: wall s per "
                          f"simulated s (ratio rodwarp / PyElastica)"),
            "rodwarp": f"dt {fmt(rw['dt_s'])} s, {fmt(rw['s_per_step']['median'] * 1e3)} ms/step: {_cost_txt(rw['cost_s_per_sim_s'])}",
            "peer": (f"PyElastica dt {fmt(pe['dt_s'])} s, {pe['pairs_registered']} pairs registered, "
                     f"{fmt(pe['s_per_step']['median'] * 1e3)} ms/step: {_cost_txt(pe['cost_s_per_sim_s'])}"),
            "ratio": p.get("rodwarp_over_pyelastica")})
        rows.append({
            "benchmark": "falling pile: PyElastica with all 4950 pairs registered (ratio rodwarp / PyElastica)",
            "rodwarp": _cost_txt(rw["cost_s_per_sim_s"]),
            "peer": (f"{fmt(pa['s_per_step']['median'] * 1e3)} ms/step, {_cost_txt(pa['cost_s_per_sim_s'])}; "
                     f"finalize {fmt(pa['finalize_s'])} s"),
            "ratio": p.get("rodwarp_over_pyelastica_all_pairs")})
        ro, po = rw["outcome"], pe.get("outcome")
        if po:
            rows.append({
                "benchmark": f"falling pile: outcome at T (hand-over centroid {p['handover']['centroid_height_m']:.4f} m, "
                             f"Z {p['handover']['Z']:.2f})",
                "rodwarp": (f"centroid {ro['centroid_height_m']:.4f} m, vz {ro['mean_vertical_velocity_m_s']:.3f} m/s, "
                            f"Z {ro['Z']:.2f}, overlap {fmt(ro['max_rod_overlap_over_d'])} d, floor "
                            f"{fmt(ro['max_floor_penetration_over_d'])} d, KE {fmt(ro['kinetic_energy_J'])} J"),
                "peer": (f"centroid {po['centroid_height_m']:.4f} m, vz {po['mean_vertical_velocity_m_s']:.3f} m/s, "
                         f"Z {po['Z']:.2f}, overlap {fmt(po['max_rod_overlap_over_d'])} d, floor "
                         f"{fmt(po['max_floor_penetration_over_d'])} d (element centres "
                         f"{fmt(po.get('max_floor_penetration_element_centres_over_d'))} d), KE "
                         f"{fmt(po['kinetic_energy_J'])} J; RMS vertex difference "
                         f"{fmt(p['rms_difference_m'] * 1e3)} mm vs displacement {fmt(ro['rms_displacement_m'] * 1e3)} mm"),
                "ratio": None})
    return rows


def plot(rec: dict, outdir) -> list[dict]:
    if rec.get("skipped"):
        return []
    plt = common.pyplot()
    charts = []
    c = rec.get("cantilever") or {}
    if c.get("pyelastica"):
        fig, axes = plt.subplots(1, 2, figsize=(14, 5.4))
        for ax, qty, rw_rows, pe_err, pe_cost in (
                (axes[0], "sag", c["rodwarp_sag"], "sag_rel_error", "cost_s_per_sim_s"),
                (axes[1], "frequency", c["rodwarp_frequency"], "frequency_rel_error", "freq_cost_s_per_sim_s")):
            edges = sorted({r["n_edges"] for r in rw_rows})
            for k, n in enumerate(edges):
                rr = [r for r in rw_rows if r["n_edges"] == n and r.get("rel_error") is not None]
                ax.plot([r["cost_s_per_sim_s"]["median"] for r in rr], [abs(r["rel_error"]) for r in rr], "o-",
                        color=plt.cm.Blues(0.4 + 0.6 * k / max(len(edges) - 1, 1)), label=f"rodwarp {n} edges (labels: dt in s)")
                for r in rr:
                    ax.annotate(f"{r['dt_s']:g}", (r["cost_s_per_sim_s"]["median"], abs(r["rel_error"])),
                                textcoords="offset points", xytext=(3, 3), fontsize=6, color="C0")
            for clamp, col in (("standard", "C3"), ("shifted", "C1")):
                rr = [r for r in c["pyelastica"] if r["clamp"] == clamp and r.get(pe_err) is not None]
                ax.plot([r[pe_cost]["median"] for r in rr], [abs(r[pe_err]) for r in rr], "s-", color=col,
                        label=f"PyElastica, {clamp} clamp")
                for r in rr:
                    ax.annotate(f"{r['n_elements']} el.", (r[pe_cost]["median"], abs(r[pe_err])),
                                textcoords="offset points", xytext=(3, -9), fontsize=6, color=col)
            for tol in TARGETS:
                ax.axhline(tol, color="gray", lw=0.8, ls=":")
                e = c["equal_accuracy"].get(f"{qty}_{tol:g}", {})
                if e.get("rodwarp"):
                    ax.plot([e["rodwarp"]["cost_s_per_sim_s"]["median"]], [abs(e["rodwarp"]["rel_error"])], "*",
                            ms=15, mfc="none", mec="C0")
                if e.get("pyelastica"):
                    ax.plot([e["pyelastica"]["cost_s_per_sim_s"]["median"]], [abs(e["pyelastica"]["rel_error"])], "*",
                            ms=15, mfc="none", mec="C3")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("wall seconds per simulated second, one rod (median)")
            ax.set_ylabel(f"|relative error| of the {'tip sag' if qty == 'sag' else 'first frequency'}")
            ax.set_title(f"Cantilever {qty}: error against cost (stars: cheapest within 2% and 1%)", fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=6.5)
        fig.suptitle(f"rodwarp vs PyElastica {rec.get('pyelastica_version')}, same run, {common.short_device(rec)}",
                     fontsize=11)
        fig.tight_layout()
        f = common.save_figure(fig, outdir / f"{NAME}_cantilever.png")
        eq = c["equal_accuracy"]

        def pick(key):
            e = eq.get(key, {})
            if not (e.get("rodwarp") and e.get("pyelastica")):
                return f"{key}: no setting of one code reaches it in the grid"
            rw, pe = e["rodwarp"], e["pyelastica"]
            return (f"rodwarp {rw['n_edges']} edges at dt {fmt(rw['dt_s'])} s ({fmt(rw['cost_s_per_sim_s']['median'])} "
                    f"s/s) vs PyElastica {pe['n_elements']} elements ({pe['clamp']} clamp) at dt {fmt(pe['dt_s'])} s "
                    f"({fmt(pe['cost_s_per_sim_s']['median'])} s/s): ratio {fmt(e.get('rodwarp_over_pyelastica'))}")

        std = [r for r in c["pyelastica"] if r["clamp"] == "standard" and r.get("sag_rel_error") is not None]
        reading = ("Error against cost, log-log, one point per setting. rodwarp: one line per edge count, points "
                   "labelled by dt (explicit bending below 0.8x its bound, implicit above). PyElastica: each element "
                   "count at 0.95x its largest stable step. Sag within 2%: " + pick("sag_0.02") + ". Sag within 1%: "
                   + pick("sag_0.01") + ". Frequency within 2%: " + pick("frequency_0.02") + ". With PyElastica's "
                   "standard clamp the error falls only as 1/n (" + ", ".join(
                       f"{r['n_elements']} el.: {100 * r['sag_rel_error']:.1f}%" for r in std)
                   + " in sag): its clamped first element is rigid; starting the rod h/2 behind the wall (shifted "
                   "clamp) makes it second order.")
        charts.append({"file": f, "title": "Cantilever: error against cost, rodwarp and PyElastica", "reading": reading})
    p = rec.get("pile") or {}
    if p and "failure" not in p:
        fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
        ax = axes[0]
        labels = ["rodwarp", f"PyElastica\n{p['pyelastica']['pairs_registered']} pairs",
                  f"PyElastica\nall {p['pyelastica_all_pairs']['pairs']} pairs"]
        vals = [p["rodwarp"]["cost_s_per_sim_s"], p["pyelastica"]["cost_s_per_sim_s"],
                p["pyelastica_all_pairs"]["cost_s_per_sim_s"]]
        med = [v["median"] for v in vals]
        err = [[v["median"] - v["min"] for v in vals], [v["max"] - v["median"] for v in vals]]
        ax.bar(range(3), med, yerr=err, color=["C0", "C1", "C3"], capsize=4)
        for k, v in enumerate(med):
            ax.annotate(f"{fmt(v)} s", (k, v), textcoords="offset points", xytext=(0, 4), ha="center", fontsize=8)
        ax.set_xticks(range(3))
        ax.set_xticklabels(labels, fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel("wall seconds per simulated second")
        ax.set_title(f"100 steel rods falling on a floor (dt: rodwarp {fmt(p['rodwarp']['dt_s'])} s, "
                     f"PyElastica {fmt(p['pyelastica']['dt_s'])} s)", fontsize=9)
        ax.grid(True, axis="y", which="both", alpha=0.3)
        ax = axes[1]
        ro, po, ho = p["rodwarp"]["outcome"], p["pyelastica"].get("outcome"), p["handover"]
        keys = [("centroid_height_m", "centroid height (m)"), ("Z", "contacts per rod Z"),
                ("rods_on_floor", "rods on the floor"), ("max_rod_overlap_over_d", "max rod overlap (d)")]
        x = np.arange(len(keys))
        w = 0.27
        for k, (o, lab, col) in enumerate(((ho, "hand-over", "gray"), (ro, "rodwarp at T", "C0"),
                                           (po, "PyElastica at T", "C1"))):
            if o is None:
                continue
            ax.bar(x + (k - 1) * w, [float(o[kk]) for kk, _ in keys], w, color=col, label=lab)
        ax.set_xticks(x)
        ax.set_xticklabels([lab for _, lab in keys], fontsize=8)
        ax.set_yscale("symlog", linthresh=1e-2)
        ax.legend(fontsize=8)
        ax.set_title(f"Outcome after {p['simulated_time_s']} s (same start state)", fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
        fig.tight_layout()
        f = common.save_figure(fig, outdir / f"{NAME}_pile.png")
        reading = (f"Left: wall time per simulated second of the same 100-rod pile over {p['simulated_time_s']} s from the "
                   f"hand-over state. rodwarp/PyElastica = {fmt(p.get('rodwarp_over_pyelastica'))} with PyElastica "
                   f"registering only the {p['pyelastica']['pairs_registered']} pairs that can meet within T, "
                   f"{fmt(p.get('rodwarp_over_pyelastica_all_pairs'))} with all {p['pyelastica_all_pairs']['pairs']} "
                   f"pairs registered; PyElastica needs dt = {fmt(p['pyelastica']['dt_s'])} s (0.95x its largest stable "
                   f"step for these steel rods, {fmt(p['pyelastica']['stability']['stable_dt_s'])} s), rodwarp takes "
                   f"{fmt(p['rodwarp']['dt_s'])} s.")
        if po:
            reading += (f" Right: both codes end in nearly the same state: centroid {ro['centroid_height_m']:.4f} m "
                        f"(rodwarp) and {po['centroid_height_m']:.4f} m (PyElastica) from {ho['centroid_height_m']:.4f} m; "
                        f"contacts per rod {ro['Z']:.2f} and {po['Z']:.2f}; RMS difference of the vertices "
                        f"{fmt(p['rms_difference_m'] * 1e3)} mm against an RMS displacement of "
                        f"{fmt(ro['rms_displacement_m'] * 1e3)} mm. Deepest floor penetration of a vertex: "
                        f"{fmt(ro['max_floor_penetration_over_d'])} d (rodwarp), {fmt(po['max_floor_penetration_over_d'])} d "
                        f"(PyElastica, whose plane contact acts on element centres: there "
                        f"{fmt(po.get('max_floor_penetration_element_centres_over_d'))} d, so a rod end can dip "
                        f"below the floor); deepest rod-rod overlap {fmt(ro['max_rod_overlap_over_d'])} d and "
                        f"{fmt(po['max_rod_overlap_over_d'])} d; kinetic energy {fmt(ro['kinetic_energy_J'])} J and "
                        f"{fmt(po['kinetic_energy_J'])} J from {fmt(ho['kinetic_energy_J'])} J.")
        charts.append({"file": f, "title": "Falling pile: cost and outcome, rodwarp and PyElastica", "reading": reading})
    return charts
