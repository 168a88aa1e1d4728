"""The laboratory protocol (docs/experiments.md): rods poured into a cylinder on a plate,
pressed by a piston to each of ``strains``, the cylinder lifted away, the plate shaken; and
what it measures that the paper's protocol does not (the fields at each compressive strain,
the lifted packing's spread, cohesion under shaking).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from rodwarp.experiments._option import param
from rodwarp.experiments._plan import Stage, Vibrate
from rodwarp.experiments._verdict import LANDED_SAMPLES, landed_samples, samples_per_cycle  # noqa: F401 (re-exported)
from rodwarp.experiments.protocols.base import Protocol
from rodwarp.validation import MAX_MU, Range

#: the stages, by the names metrics.csv's ``stage`` column carries (a press stage is PRESS and
#: its strain, e.g. ``press0.05``)
POUR, LIFT, SHAKE, PRESS = "pour", "lift", "shake", "press"
#: the walls: the floor (the shaken plate), the cylinder the rods are poured into, the piston
FLOOR, TUBE, PISTON = "floor", "tube", "piston"
#: volume fraction of a random packing of long rods, phi alpha = 5.4 (Philipse 1996; docs/experiments.md):
#: the laboratory protocol fills its cylinder with the rods that take its fill height at this fraction
PHI_ALPHA = 5.4

#: the piston starts this many rod lengths above the top of the pour column
PISTON_CLEARANCE = 0.5
#: what summary.json keeps of each strain's field statistics (rodwarp.analysis.field_statistics)
STRAIN_STATS = ("mean_phi", "mean_S", "mean_c", "mean_e", "mean_n", "std_e", "cv_e", "median_e", "q1_e", "q3_e",
                "iqr_e", "e_lb", "outlier_fraction", "n_valid_voxels", "radius", "spacing")


@dataclass(frozen=True)
class LabParams:
    """The laboratory protocol's own parameters: the cylinder and its fill, the pour, the
    strains and their durations, the lift, the container's friction."""

    container_radius: float = param(1.0, "lab: radius of the cylinder the rods are poured into, in rod lengths.",
                                     "Rc",
          range=Range(ge=0.6, le=100, hint="in rod lengths: a rod must fit across the cylinder in any direction"))
    fill_height: float = param(1.0, f"lab: without --n-rods, as many rods as fill the cylinder to this height (rod "
                                     f"lengths) at a random packing's phi = {PHI_ALPHA:g} / alpha.", "H",
          range=Range(gt=0, le=100, hint="in rod lengths"))
    pour_duration: float = param(1.0, "lab: time the poured rods fall and settle in the cylinder (s).", "pdur",
          range=Range(gt=0, le=100, unit="s", hint="the rods need time to fall and settle"))
    strains: tuple = param((), "lab: compressive strains the piston presses the poured packing to in turn, "
                                "'E1,E2,...' (e.g. 0,0.05,0.1,0.15); the fields at each in summary.json.", "eps",
          range=Range(ge=0, lt=0.5, each=True, hint="compressive strains are fractions of the packing's height (the paper's 0 to 0.15)"))
    press_duration: float = param(0.5, "lab: time of each strain (s): pressed over its first half, held over "
                                        "the second.", "prdur",
          range=Range(gt=0, le=1000, unit="s"))
    lift_duration: float = param(1.0, "lab: time the packing stands (or spreads) after the cylinder is lifted "
                                       "away, before the shaking (s); the test when --duration is 0.", "ldur",
          range=Range(ge=0, le=1000, unit="s", hint="0 shakes right after the lift"))
    wall_mu: float | None = param(None, "lab: friction coefficient of the cylinder's wall and the piston "
                                         "(default --mu; the plate keeps --mu).", "muw",
          range=Range(ge=0, le=MAX_MU, hint="0 makes the container's wall and the piston frictionless"))


def lab_packing(params, device, label: str = "cylinder"):
    """The rods released for a pour: ``params.rods`` straight rods at uniform random positions
    and isotropic directions (random sequential addition, seed ``params.seed``), each wholly
    inside the cylinder the rods are poured into (radius
    :attr:`~rodwarp.experiments.ProtocolParams.pour_radius` about the z axis: the lab's
    container, the excitation experiment's tube), in a column from one diameter above the floor
    to :meth:`~rodwarp.experiments.ProtocolParams.pour_height`.

    Returns
    -------
    RodSet
        The rods (m), ``box`` the column's bounding box; ``attrs`` name the pour (``label``),
        its radius and height.
    """
    from rodwarp.experiments._packing import random_packing

    rc = params.pour_radius
    height = params.pour_height()
    rods = random_packing(params.rods, params.length, params.diameter, (2 * rc, 2 * rc, height),
                          n_vertices=params.n_vertices, seed=params.seed, device=device, cylinder=rc)
    shift = np.array([-rc, -rc, params.diameter])
    out = rods.with_points(rods.points + shift)
    out.box = rods.box + shift
    out.attrs.update(rods.attrs)
    out.attrs.update({"pour": label, "pour_radius_m": rc, "pour_height_m": height})
    return out


def lab_walls(builder, params, rods) -> tuple[np.ndarray, np.ndarray]:
    """Add the lab's walls to ``builder``: the plate (``floor``, z = 0, shaken), the cylinder
    (``tube``, radius ``container_radius`` l about the z axis) and the ``piston`` (the
    half-space below it, PISTON_CLEARANCE l above the rods, pressing down); the tube and the
    piston take ``params.wall_mu`` when given. Returns the
    scene's box (lo, hi) for the figures (m)."""
    from rodwarp.sim.walls import Cylinder, Plane

    rc = params.container_radius * params.length
    top = float(rods.bounding_box()[1][2]) + PISTON_CLEARANCE * params.length
    builder.add_wall(Plane.make((0.0, 0.0, 1.0), 0.0, moving=True, name=FLOOR))
    # --wall-mu: the container's wall and the piston alone (None: the model's mu); the plate
    # carries the pile and keeps the rods' mu
    builder.add_wall(Cylinder.make((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), rc, name=TUBE, mu=params.wall_mu))
    builder.add_wall(Plane.make((0.0, 0.0, -1.0), -top, moving=True, name=PISTON, mu=params.wall_mu))
    return np.array([-rc, -rc, 0.0]), np.array([rc, rc, top])


def packing_top(model, x: np.ndarray) -> float:
    """Height (m) of the packing's highest surface point above z = 0 (the plate at rest)."""
    r = model.radius_np[model.vertex_rod_np]
    return float(np.max(x[:, 2] + r))


#: the spread radius holds this share of the rods' centroids: a percentile, so that one rod
#: rolling away on the floor does not set it (the largest distance was 12 Rc at alpha 38)
SPREAD_QUANTILE = 0.9


def spread_radius(model, x: np.ndarray) -> float:
    """Horizontal distance (m) from the cylinder's axis within which SPREAD_QUANTILE of the
    rods' mass centroids lie: the lifted packing's spread (below ``container_radius`` l while
    the cylinder holds it)."""
    from rodwarp.experiments._verdict import rod_centroids

    c = rod_centroids(x, model.vertex_rod_np, model.mass_np, model.n_rods)
    return float(np.quantile(np.hypot(c[:, 0], c[:, 1]), SPREAD_QUANTILE))


def piston_height(model, control, t: float) -> float | None:
    """Height (m) of the piston's face at time t, None when it is not in place."""
    for k, w in enumerate(model.walls):
        if w.name == PISTON and control.on[k]:
            shift = control.drive.displacement(t) if control.moving[k] else 0.0
            return float(-w.offset - shift)
    return None


def strain_fields(model, sim_rods, x, contacts, params, top: float, device):
    """The fields of the pressed packing (the analysis of ``rodwarp analyze``: ball radius
    sqrt(d l), spacing R / 2) in the box inscribed in the cylinder, from the plate to the
    piston's face at ``top`` (m): balls that leave it are not counted.

    Returns
    -------
    (Fields or None, dict)
        The fields and the kept statistics (:data:`STRAIN_STATS`); (None, {"error": ...})
        when no ball fits.
    """
    from rodwarp.analysis import compute_fields, field_statistics
    from rodwarp.errors import RodwarpError

    half = params.container_radius * params.length / math.sqrt(2.0)
    rods = sim_rods.with_points(x)
    rods.contacts = contacts
    domain = np.array([[-half, -half, 0.0], [half, half, top]])
    try:
        f = compute_fields(rods, domain=domain, device=device)
        st = field_statistics(f, power_laws=False)
    except RodwarpError as e:  # no ball fits the pressed packing
        return None, {"error": str(e)}
    return f, {k: st.get(k) for k in STRAIN_STATS}


def landed_heights(t: np.ndarray, y: np.ndarray, freq: float) -> tuple[np.ndarray, np.ndarray]:
    """Fig. 1E's y_c(N) / y_c(0) for a packing the plate throws: per whole cycle N = 1, 2, ...
    (the samples with N - 1 < t f <= N), the lowest of the sampled heights ``y`` (the centroid
    above the plate over its value before the shaking).

    At a/g > 1 the packing leaves the plate every cycle; a sample at one fixed phase catches it
    in flight (y_c / y_c(0) of 3 to 4 at alpha 38 with the plate at its lowest point), while the
    lowest height of a cycle is the packing landed on the plate. It needs several samples per
    cycle (``--save-every`` well below 1 / f). ``t`` is time since the shaking began (s).

    Returns
    -------
    (cycles, heights)
        The cycle numbers N and their lowest heights; cycles without a sample are left out.
    """
    cyc, idx = landed_samples(t, y, freq)
    return cyc, np.asarray(y, dtype=float)[idx]


def landed_sampling_warning(params) -> str | None:
    """Why Fig. 1E's landed heights of a shaken lab run cannot be trusted, or None: the plate
    throws the packing (a/g > 1) and ``save_every`` gives fewer than LANDED_SAMPLES samples per
    cycle, so the lowest sample of a cycle may be in flight."""
    if params.duration <= 0 or params.freq <= 0 or params.a_over_g <= 1.0:
        return None
    per = samples_per_cycle(params)
    if per >= LANDED_SAMPLES - 1e-9:
        return None
    return (f"--save-every {params.save_every:g} s gives {per:.3g} samples per cycle at {params.freq:g} Hz; at "
            f"a/g = {params.a_over_g:.2g} the plate throws the packing, and the landed height of Fig. 1E needs "
            f"at least {LANDED_SAMPLES} (--save-every {1.0 / (LANDED_SAMPLES * params.freq):g} or less)")


def _stage_rows(rows, name: str) -> list:
    return [r for r in rows if r["stage"] == name]


def lab_summary(params, model, rows, loop, stages, thresholds) -> dict:
    """summary.json's ``lab`` block: the scene, the pour, each strain, the lifted packing and
    the shaking judged by cohesion (docs/experiments.md, "Judging a packing that is thrown").

    The lift: the mass centroid's height and the spread radius at its end over their values
    just before (``height_kept_after_lift``, ``spread_over_container``: above 1 the rods left
    the container's footprint). The shaking: y_c(t) / y_c(0) at each sample (Fig. 1E, x axis
    cycles N = (t - t_0) f), and cohesion alone: the largest contact cluster's share f(t), its
    persistence tau_f (the share of the shaking with f >= the verdict's cluster threshold) and
    the rods separated from it at the end, 1 - f. Height is no criterion while the plate throws
    the packing: at A = 25 mm, 5 Hz (a/g = 2.5) it leaves the plate every cycle.
    """
    num = lambda r, k: None if r is None or r.get(k) in ("", None) else float(r[k])  # noqa: E731
    names = [s.name for s in stages]
    pour = _stage_rows(rows, POUR)
    out = {"container_radius_m": params.container_radius * params.length, "pour_height_m": params.pour_height(),
           "n_rods": model.n_rods, "fill_rule": None if params.n_rods is not None else
           f"round(4 (Rc/l)^2 (H/l) 5.4 alpha) rods fill the cylinder to H = {params.fill_height:g} l at "
           "phi = 5.4 / alpha", "stages": names,
           "pour": {"centroid_height_m": num(pour[-1], "centroid_height"),
                    "kinetic_energy_J": num(pour[-1], "kinetic_energy"),
                    "contacts_per_rod": num(pour[-1], "contacts_per_rod")},
           "strains": loop.marks.get("strains", [])}
    if LIFT in names:
        i = names.index(LIFT)
        before = [r for r in rows if r["stage"] == names[i - 1]][-1]
        lift = _stage_rows(rows, LIFT)
        rc = params.container_radius * params.length
        out["lift"] = {"height_kept_after_lift": num(lift[-1], "centroid_height") / num(before, "centroid_height"),
                       "spread_radius_m": num(lift[-1], "spread_radius"),
                       "spread_over_container": num(lift[-1], "spread_radius") / rc,
                       "largest_cluster_fraction": num(lift[-1], "largest_cluster_fraction"),
                       "kinetic_energy_J": num(lift[-1], "kinetic_energy")}
    if SHAKE in names:
        out["shake"] = shake_result(params, rows, loop.stage_t0[SHAKE], thresholds)
    return out


def shake_result(params, rows, t0: float, thresholds) -> dict:
    """summary.json's ``lab.shake`` block from the metrics rows (dicts as in metrics.csv) of a
    run whose shaking began at ``t0`` (s): y_c(t) / y_c(0) at each sample and its landed value
    per cycle (:func:`landed_heights`, Fig. 1E), and the cohesion verdict: the largest contact
    cluster's share f(t), its persistence tau_f (the share of the shaking with f >= the
    verdict's cluster threshold) and the rods separated from it at the last sample, 1 - f. A
    run still going gives the shaking so far."""
    from rodwarp.experiments import _verdict as vd

    shake = [r for r in _stage_rows(rows, SHAKE) if float(r["time"]) > t0]
    y0 = float([r for r in rows if float(r["time"]) <= t0][-1]["centroid_height"])
    t = np.array([float(r["time"]) for r in shake])
    f = np.array([float(r["largest_cluster_fraction"]) for r in shake])
    tau_f = vd.persistence(t, t0, f >= thresholds.cluster)
    y = np.array([float(r["centroid_height"]) for r in shake]) / y0
    k_cyc, y_landed = landed_heights(t - t0, y, params.freq)
    return {"freq_hz": params.freq, "amplitude_m": params.amplitude, "a_over_g": params.a_over_g,
            "shaken_s": float(t[-1] - t0),
            "cycles": ((t - t0) * params.freq).tolist(),
            "centroid_height_ratio": y.tolist(),
            "landed": {"cycle": k_cyc.tolist(), "centroid_height_ratio": y_landed.tolist(),
                       "samples_per_cycle": samples_per_cycle(params),
                       "warning": landed_sampling_warning(params),
                       "rule": "per cycle N (samples with N-1 < (t - t0) f <= N), the lowest "
                               "centroid height above the plate over y_c(0): the packing landed, "
                               "not in flight"},
            "cohesion": {"persistence": tau_f,
                         "largest_cluster_fraction": float(f[-1]), "separated": float(1.0 - f[-1]),
                         "cohesive": bool(f[-1] >= thresholds.cluster and tau_f >= thresholds.persistence),
                         "rule": f"cohesive = f >= {thresholds.cluster:g} at the end and f >= "
                                 f"{thresholds.cluster:g} for at least {thresholds.persistence:g} of "
                                 "the shaking (height is not judged: the plate throws the packing)"}}


def lab_columns(model, x, control, t) -> dict:
    """metrics.csv's columns of the lab protocol: the piston's face height (m; empty when it is
    out) and the spread radius (m)."""
    top = piston_height(model, control, t)
    return {"piston_height": "" if top is None else top, "spread_radius": spread_radius(model, x)}


def lab_plan(params) -> tuple[Stage, ...]:
    """The laboratory protocol's stages: the rods poured into the cylinder settle
    (``pour_duration``); pressed by the piston to each of ``strains`` in turn, each held until
    the end of its ``press_duration``; the cylinder (and piston) lifted away, the packing left
    to stand or spread (``lift_duration``); the plate (the floor) shaken at ``freq``,
    ``amplitude`` for ``duration``, the test. Without shaking the lift is the test. Stages of
    zero duration are left out."""
    stages = [Stage(POUR, params.pour_duration, walls_out=(PISTON,), moving=(), snapshot=f"after {POUR}",
                    title="pour", option="--pour-duration")]
    prev = 0.0
    for e in params.strains:
        name = f"{PRESS}{e:g}"
        stages.append(Stage(name, params.press_duration, PressTo(prev, float(e)), moving=(PISTON,),
                            snapshot=f"after {name}", title=f"press to strain {e:g}", option="--press-duration"))
        prev = float(e)
    shake = params.duration > 0
    if params.lift_duration > 0:
        stages.append(Stage(LIFT, params.lift_duration, walls_out=(TUBE, PISTON), moving=(), test=not shake,
                            snapshot=f"after {LIFT}", title="container lifted", option="--lift-duration"))
    if shake:
        stages.append(Stage(SHAKE, params.duration, Vibrate(params.amplitude, params.freq, from_rest=True),
                            walls_out=(TUBE, PISTON), moving=(FLOOR,), test=True, title="shaking",
                            option="--duration"))
    return tuple(stages)


def piston_travel(model, height0: float, strain: float) -> float:
    """How far the piston has come down (m) when the packing, ``height0`` tall (m, above the
    floor) when pressing began, is at compressive ``strain``."""
    top = next(w for w in model.walls if w.name == PISTON)
    return -top.offset - height0 * (1.0 - strain)  # the piston is the half-space z <= -offset


@dataclass(frozen=True)
class PressTo:
    """The piston presses the packing from compressive strain ``start`` to ``strain`` over the
    first half of its stage, then holds: strains of the packing's height when the first press
    began (``marks["height0"]``, measured by :meth:`begin`). At its end the pressed packing's
    fields, rods and contacts are written (:func:`strain_record`)."""

    start: float
    strain: float

    def apply(self, control, model, duration: float, t0: float, marks: dict | None) -> None:
        if marks is None or "height0" not in marks:  # sizing a run: at rest
            control.set_ramp(0.0, duration, direction=(0.0, 0.0, -1.0), start_time=t0)
            return
        d0, d1 = (piston_travel(model, marks["height0"], e) for e in (self.start, self.strain))
        ramp = 0.5 * duration
        control.set_ramp((d1 - d0) / ramp, ramp, direction=(0.0, 0.0, -1.0), start_time=t0, start=d0)

    def begin(self, model, state, marks: dict) -> None:
        if "height0" not in marks:
            marks["height0"] = packing_top(model, state.positions())

    def end(self, stage, run) -> None:
        run.marks.setdefault("strains", []).append(strain_record(stage, self.strain, run))


def strain_record(stage, strain: float, run) -> dict:
    """At the end of a press stage: the strain reached, the rest it came to, and the fields
    of the pressed packing (written to ``fields_<stage>.npz``, its rods and contacts to
    ``rods_<stage>.npz``; statistics returned). ``run`` is the loop's
    :class:`~rodwarp.experiments._loop.StageEnd`."""
    from rodwarp.rodset import contacts_per_rod
    from rodwarp.sim import rod_contacts

    model, state, params, height0 = run.model, run.state, run.params, run.marks["height0"]
    x = state.positions()
    c = rod_contacts(model, state, run.points)
    top = piston_height(model, run.control, state.time)
    f, stats = strain_fields(model, run.rods, x, c, params, top, model.device)
    name = f"fields_{stage.name}.npz"
    if f is not None:
        f.save(run.outdir / name)
    # the pressed packing itself (rods and contacts, m): its fields can be recomputed under
    # any convention, grid or region (scripts/ct_like_for_like.py)
    pressed = run.rods.with_points(x)
    pressed.contacts = c
    pressed.attrs.update({"stage": stage.name, "strain": float(strain),
                          "piston_height_m": float(top), "time_s": float(state.time)})
    pressed.save(run.outdir / f"rods_{stage.name}.npz")
    speed = np.linalg.norm(state.velocities(), axis=1)
    num = lambda v: None if v is None else float(v)  # noqa: E731
    return {"stage": stage.name, "strain": float(strain), "height0": float(height0),
            "piston_height": float(top), "strain_reached": 1.0 - float(top) / float(height0),
            "packing_top": packing_top(model, x),
            "max_speed": float(speed.max()), "kinetic_energy": float(run.solver.energy(state)["kinetic"]),
            "contacts_per_rod": contacts_per_rod(model.n_rods, c),
            "fields": name if f is not None else None, "rods": f"rods_{stage.name}.npz",
            **{k: num(v) if not isinstance(v, str) else v for k, v in stats.items()}}


class LabProtocol(Protocol):
    """The laboratory protocol as a plug-in of :func:`rodwarp.experiments.run_protocol`."""

    name = "lab"
    help = "rods poured into a cylinder, pressed by a piston to --strains, the cylinder lifted away, the plate shaken at --freq, --amplitude for --duration; docs/experiments.md"
    Params = LabParams
    fields = tuple(f.name for f in fields(LabParams))
    poured = True

    def plan(self, params):
        return lab_plan(params)

    def packing(self, params, device):
        return lab_packing(params, device)

    def walls(self, builder, params, rods):
        return lab_walls(builder, params, rods)

    def columns(self, model, x, control, t) -> dict:
        return lab_columns(model, x, control, t)

    def check(self, p) -> None:
        """The lab protocol's own checks (one line each)."""
        from rodwarp.validation import fail

        if p.duration == 0 and p.lift_duration == 0:
            fail("--duration 0 and --lift-duration 0 leave the lab protocol without a test; give the shaking a "
                 "--duration or the lifted packing a --lift-duration")
        strains = tuple(p.strains)
        if any(b < a for a, b in zip(strains, strains[1:])):
            fail(f"--strains must not decrease (the piston presses further at each), got "
                 f"{','.join(f'{e:g}' for e in strains)}")

    def rods(self, params) -> int:
        """Rods that fill the cylinder (radius ``container_radius`` l) to ``fill_height`` l at
        phi = 5.4 / alpha: pi Rc^2 H phi / (pi d^2 l / 4) = 4 (Rc/l)^2 (H/l) 5.4 alpha."""
        return max(1, int(round(4.0 * params.container_radius**2 * params.fill_height * PHI_ALPHA * params.alpha)))

    def pour_radius(self, params) -> float:
        """The container's radius, ``container_radius`` rod lengths (m)."""
        return params.container_radius * params.length

    def summary(self, params, model, rows, loop, stages, thresholds):
        return "lab", lab_summary(params, model, rows, loop, stages, thresholds)

    def notes(self, params) -> list[str]:
        why = landed_sampling_warning(params)
        return [] if why is None else [why]


LAB = LabProtocol()
