"""The paper's excitation experiment (Fig. 1C-F), as one protocol: ``rodwarp simulate
--protocol excitation``.

Everything the protocol is lives here: its defaults and where each comes from
(:data:`PAPER_DEFAULTS`, :func:`resolve_defaults`), its scene (:func:`excitation_packing`,
:func:`excitation_walls`), its stages (:func:`excitation_plan`), its checks
(:func:`check_excitation`), its columns in metrics.csv (:func:`excitation_columns`) and its
block of summary.json with the paper's measures (:func:`excitation_summary`, :func:`tau_rule`).
The stepping loop, checkpoints and outputs are every protocol's
(:func:`rodwarp.experiments.run_protocol`), reached through :data:`EXCITATION`.

The experiment, from the paper's Materials and Methods, "Mechanical Testing" (docs/experiments.md):
N ~ 1.25e6 / (d l^2) steel rods (d and l in mm) are deposited into an inner tube standing in a
cylindrical container 150 mm across and 150 mm tall; the tube is removed; the container is
shaken vertically at 5 Hz and 25 mm. Fig. 1E plots y_c(t) / y_c(0) against cycles; Fig. 1F
tau = t_entangled / T with T = 100 s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from rodwarp.experiments._option import param
from rodwarp.experiments._plan import Stage, Vibrate
from rodwarp.experiments._verdict import samples_per_cycle
from rodwarp.experiments.protocols.base import Protocol
from rodwarp.validation import Range
from rodwarp.experiments.protocols.lab import FLOOR, TUBE

#: the name of the shaken container's side wall (the floor is :data:`FLOOR`)
CONTAINER = "container"
#: the stages: the rods fall into the tube and settle; the tube is removed and the packing
#: stands or slumps against nothing but the floor (and the container's wall far away); shaking
POUR, RELEASE, SHAKE = "pour", "release", "shake"

#: the experiments' rods, alpha -> (length, diameter) in m (the paper's Table S4, as the authors'
#: data repository lists them): 25 x 0.66, 50 x 0.76, 50 x 0.66, 50 x 0.5 and 50 x 0.25 mm
PAPER_RODS = {38: (0.025, 0.66e-3), 66: (0.05, 0.76e-3), 76: (0.05, 0.66e-3), 100: (0.05, 0.5e-3),
              200: (0.05, 0.25e-3)}
#: rod length (m) of an alpha that is not one of the experiments' (Fig. 1D's 333 and Fig. 1E's
#: 125 are 50 mm rods in the paper, as are four of its five experimental rods)
OTHER_LENGTH = 0.05
#: N d l^2 in mm^3: "approximately N = 1.25e6 / (d l^2) steel rods" (Methods, "Mechanical Testing")
N_DL2_MM3 = 1.25e6
#: the inner tube's diameter (m). The paper gives none. It fixes a total packing volume (N rods
#: at Z ~ 6 contacts per rod, phi alpha = Z: V = pi N d l^2 / (4 Z) = 1.6e5 mm^3 for every
#: alpha); a tube of diameter D holds that volume to a height 4 V / (pi D^2). 60 mm makes the
#: poured packing about as tall as it is wide (D = (4 V / pi)^(1/3) = 59 mm), a compact clump
#: like Fig. 1C-D's, with room for a 50 mm rod at any tilt above 34 degrees; 100 mm (the second
#: diameter the experiments measure, docs/experiments.md) makes a layer about 20 mm tall
TUBE_DIAMETER = 0.06
#: every default of the protocol: value, source (``paper``: its text, cited; ``rodwarp``: a choice the
#: paper leaves open) and why (docs/experiments.md, "The excitation experiment")
PAPER_DEFAULTS = {
    "gravity": (9.81, "paper", "laboratory gravity (the experiment, not the simulations' rescaled 0.5)"),
    "freq": (5.0, "paper", "Methods, Mechanical Testing: 'a frequency of 5 Hz'"),
    "amplitude": (0.025, "paper", "Methods, Mechanical Testing: 'an amplitude of 25 mm'"),
    "duration": (100.0, "paper", "Fig. 1F: T = 100 s"),
    "container_diameter": (0.15, "paper", "Methods, Mechanical Testing: 'a diameter of 150 mm'"),
    "container_height": (0.15, "paper", "Methods, Mechanical Testing: 'a height of 150 mm'"),
    "tube_diameter": (TUBE_DIAMETER, "rodwarp", "not in the paper: the packing's fixed volume made as tall as wide "
                                     "(rodwarp.experiments.protocols.excitation.TUBE_DIAMETER)"),
    "mu": (0.2, "paper", "the paper's simulations (Results: 'a fixed friction coefficient mu = 0.2'); not given for "
                     "the experiment's steel"),
    "young": (200e9, "paper", "steel rods (Methods, Packing preparation: stainless steel)"),
    "density": (7850.0, "paper", "steel rods (Methods, Packing preparation: stainless steel)"),
    "pour_duration": (1.0, "rodwarp", "not in the paper: time for the rods to fall through the tube and settle"),
    "lift_duration": (1.0, "rodwarp", "not in the paper: the packing left to stand after the tube is removed, "
                           "before the excitation"),
    "iterations": (20, "rodwarp", "Gauss-Seidel sweeps: at the generic 10 the shaken container's landings blew "
                                  "up (rods overlapping by 0.32 d at t = 6.0 s, alpha 100 seed 0; 0.27 d at 9.6 s, "
                                  "alpha 66 seed 0); 20 took alpha 100 past it at 1.4 times the cost (halving the "
                                  "step did at 2.5 times)"),
    "save_every": (0.025, "rodwarp", "rodwarp: 8 samples per 5 Hz cycle, so that each cycle's landed height is sampled"),
    "fields_every": (0.0, "rodwarp", "rodwarp: the entanglement fields series is off (the thrown packing is judged by "
                          "its height and cluster)"),
}
#: the fields of :class:`~rodwarp.experiments.ProtocolParams` that only the excitation protocol uses
EXCITATION_FIELDS = ("container_diameter", "container_height", "tube_diameter")
#: a packing is "entangled" at a cycle's landing when it keeps at least this share of its height,
#: y_c / y_c(0) (:func:`tau_rule`): halfway between a standing clump (1) and the floor-covering
#: layer the collapsed packings of the container settle into (0.24-0.30 measured at alpha 66 and
#: 100, docs/experiments.md); TAU_HEIGHT_RANGE are the thresholds tau is also given at
TAU_HEIGHT = 0.5
TAU_HEIGHT_RANGE = (0.4, 0.6)
#: a unit "forms" (Fig. 1E (i)) when the landed cluster share rises by at least this much above
#: its lowest value so far and holds for FORM_CYCLES cycles, or when the packing, having been
#: judged not entangled for FORM_CYCLES cycles, is judged entangled for FORM_CYCLES again
FORM_RISE = 0.1
FORM_CYCLES = 5


@dataclass(frozen=True)
class ExcitationParams:
    """The excitation experiment's own parameters (with the lab's ``pour_duration`` and
    ``lift_duration``): the shaken container and the inner tube."""

    container_diameter: float | None = param(None, "excitation: diameter of the shaken container (m; default the "
                                                    "paper's 0.15; 0: an open plate).", "Dc",
          range=Range(ge=0, le=10, unit="m", hint="0 shakes the packing on an open plate"))
    container_height: float | None = param(None, "excitation: height of the container (m; default the paper's "
                                                  "0.15): no rod may rise above its rim.", "Hc",
          range=Range(gt=0, le=10, unit="m"))
    tube_diameter: float | None = param(None, "excitation: diameter of the inner tube the rods are poured into "
                                               "(m; default 0.06, the paper gives none: docs/experiments.md).", "Dt",
          range=Range(gt=0, le=10, unit="m"))


def paper_length(alpha: float) -> float:
    """Rod length (m) of the experiment at ``alpha``: the experiments' rod where alpha is one of
    theirs (:data:`PAPER_RODS`, nearest integer), else :data:`OTHER_LENGTH`."""
    k = int(round(alpha))
    return PAPER_RODS[k][0] if k in PAPER_RODS and abs(alpha - k) < 1e-9 else OTHER_LENGTH


def paper_rod_count(diameter: float, length: float) -> int:
    """The paper's N = 1.25e6 / (d l^2), d and l in mm (Methods, "Mechanical Testing")."""
    return max(1, int(round(N_DL2_MM3 / ((diameter * 1e3) * (length * 1e3) ** 2))))


def resolve_defaults(params, explicit=None):
    """``params`` with every option the user did not give set to the experiment's value.

    Parameters
    ----------
    params : ProtocolParams
        With ``protocol`` excitation (others are returned unchanged).
    explicit : iterable of str or None
        Field names the user gave; None: those that differ from ProtocolParams' own defaults
        (what an API caller passed).

    Returns
    -------
    ProtocolParams
        Gravity, drive, duration, container, tube, friction, steel and sampling from
        :data:`PAPER_DEFAULTS`, the rod length from :func:`paper_length` (N stays None: the
        paper's formula, :meth:`~rodwarp.experiments.ProtocolParams.rods`).
    """
    if params.protocol != "excitation":
        return params
    base = {f.name: f.default for f in fields(params)}
    if explicit is None:
        explicit = {k for k, v in base.items() if _differs(getattr(params, k), v)}
    explicit = set(explicit)
    change = {k: v for k, (v, _, _) in PAPER_DEFAULTS.items() if k not in explicit}
    if "length" not in explicit:
        change["length"] = paper_length(params.alpha)
    return replace(params, **change)


def _differs(a, b) -> bool:
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)):
        return list(a) != list(b)
    return a != b


def sources(params) -> dict:
    """Each of the experiment's parameters, its value and where it came from: ``paper`` (the
    Methods or a figure, cited), ``rule`` (computed from the paper's rule), ``rodwarp`` (a choice
    the paper leaves open, stated) or ``option`` (the user's)."""
    out = {}
    for k, (v, src, why) in PAPER_DEFAULTS.items():
        val = getattr(params, k)
        src = src if val == v else "option"
        out[k] = {"value": val, "source": src, "why": why if src != "option" else "given"}
    lab_l = paper_length(params.alpha)
    out["length"] = {"value": params.length, "source": "paper" if params.length == lab_l else "option",
                     "why": ("Table S4: the experiments' rod" if int(round(params.alpha)) in PAPER_RODS else
                             "50 mm, the experiments' length for alphas not among their rods")
                     if params.length == lab_l else "given"}
    out["n_rods"] = {"value": params.rods, "source": "rule" if params.n_rods is None else "option",
                     "why": "Methods, Mechanical Testing: N = 1.25e6 / (d l^2), d and l in mm"
                     if params.n_rods is None else "given"}
    return out


def rod_count(params) -> int:
    """Rods of the experiment: ``n_rods``, else the paper's N for d = l / alpha (the plug-in's
    count behind :meth:`~rodwarp.experiments.ProtocolParams.rods`)."""
    return params.n_rods if params.n_rods is not None else paper_rod_count(params.diameter, params.length)


def packing_volume(params, phi_alpha: float = 5.4) -> float:
    """Volume (m^3) the rods fill at phi = ``phi_alpha`` / alpha (the random contact equation's
    phi alpha = 5.4 by default)."""
    return rod_count(params) * math.pi / 4 * params.diameter ** 2 * params.length / (phi_alpha / params.alpha)


def excitation_plan(params) -> tuple:
    """The stages: ``pour`` (floor, tube and container in place, nothing moving; the rods fall
    into the tube and settle), ``release`` (the tube removed; the packing stands or slumps;
    ``lift_duration``), ``shake`` (the floor and the container's wall follow the drive from rest
    at its lowest point, ``freq``, ``amplitude``, ``duration``: the test). Without shaking
    (``duration`` 0) the release is the test (Fig. 1A-B)."""
    shake = params.duration > 0
    out = [Stage(POUR, params.pour_duration, moving=(), snapshot=f"after {POUR}", title="pour",
                 option="--pour-duration")]
    if params.lift_duration > 0:
        out.append(Stage(RELEASE, params.lift_duration, walls_out=(TUBE,), moving=(), test=not shake,
                         snapshot=f"after {RELEASE}", title="tube removed", option="--lift-duration"))
    if shake:
        moving = (FLOOR, CONTAINER) if params.container_diameter > 0 else (FLOOR,)  # 0: an open plate
        out.append(Stage(SHAKE, params.duration, Vibrate(params.amplitude, params.freq, from_rest=True),
                         walls_out=(TUBE,), moving=moving, test=True, title="shaking", option="--duration"))
    return tuple(out)


def excitation_packing(params, device):
    """The rods released for the pour: the paper's N (:meth:`~rodwarp.experiments.
    ProtocolParams.rods`) at random positions and isotropic directions, each wholly inside the
    tube, in a column dilute enough (phi alpha = 2) that they fall as through the experiment's
    sieve (:func:`~rodwarp.experiments.protocols.lab.lab_packing`, the lab protocol's pour)."""
    from rodwarp.experiments.protocols.lab import lab_packing

    return lab_packing(params, device, label="tube")


def excitation_walls(builder, params, rods):
    """Add the floor (z = 0, shaken), the container's side wall (radius ``container_diameter``
    / 2 about the z axis, shaken with the floor; none when the diameter is 0, an open plate) and
    the tube (radius ``tube_diameter`` / 2, fixed, removed before the shaking). The walls are
    unbounded in height; the run checks that no rod rises above the container's rim
    (:func:`excitation_summary`). Returns the scene's box (lo, hi) for the figures (m)."""
    from rodwarp.sim.walls import Cylinder, Plane

    builder.add_wall(Plane.make((0.0, 0.0, 1.0), 0.0, moving=True, name=FLOOR))
    rc = 0.5 * params.container_diameter
    if rc > 0:
        builder.add_wall(Cylinder.make((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), rc, moving=True, name=CONTAINER))
    builder.add_wall(Cylinder.make((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), params.pour_radius, name=TUBE))
    r = max(rc, params.pour_radius)
    top = max(float(rods.bounding_box()[1][2]), params.container_height)
    return np.array([-r, -r, 0.0]), np.array([r, r, top])


def excitation_columns(model, x, control, t) -> dict:
    """metrics.csv's columns of the experiment: the spread radius (m, :func:`~rodwarp.experiments.
    protocols.lab.spread_radius`), the highest surface point above the floor (m, ``top_height``) and the
    highest rod's lowest point above the floor (m, ``highest_rod_bottom``: a rod wholly above
    the container's rim could leave a real container)."""
    from rodwarp.experiments.protocols.lab import spread_radius

    floor = control.floor_height(t)
    floor = 0.0 if floor is None else floor
    rid = model.vertex_rod_np
    r = model.radius_np[rid]
    bottom = np.full(model.n_rods, np.inf)
    np.minimum.at(bottom, rid, x[:, 2] - r)
    return {"spread_radius": spread_radius(model, x), "top_height": float(np.max(x[:, 2] + r) - floor),
            "highest_rod_bottom": float(bottom.max() - floor)}


def check_excitation(p) -> None:
    """The experiment's own checks (one line each, before any work)."""
    from rodwarp.validation import fail

    if p.duration == 0 and p.lift_duration == 0:
        fail("--duration 0 and --lift-duration 0 leave the excitation experiment without a test; give the shaking "
             "a --duration or the released packing a --lift-duration")
    rt, rc, l = 0.5 * p.tube_diameter, 0.5 * p.container_diameter, p.length
    if rt < 0.6 * l:
        fail(f"--tube-diameter {p.tube_diameter * 1e3:g} mm is narrower than 1.2 rod lengths ({1.2 * l * 1e3:g} mm): "
             f"random rods cannot be placed in it; widen the tube")
    if rc > 0 and rt >= rc - p.diameter:
        fail(f"--tube-diameter {p.tube_diameter * 1e3:g} mm does not fit inside --container-diameter "
             f"{p.container_diameter * 1e3:g} mm; make the tube narrower than the container")
    n = rod_count(p)
    h = packing_volume(p) / (math.pi * rt * rt)
    if h > p.container_height:
        fail(f"{n} rods of {p.length * 1e3:g} mm x {p.diameter * 1e3:.3g} mm fill the {p.tube_diameter * 1e3:g} mm tube "
             f"to about {h * 1e3:.0f} mm at phi alpha = 5.4, above the container's {p.container_height * 1e3:g} mm; "
             f"lower --n-rods or widen --tube-diameter")
    if p.a_over_g > 1 and samples_per_cycle(p) < 4 - 1e-9 and p.duration > 0:
        fail(f"--save-every {p.save_every:g} s gives {samples_per_cycle(p):.3g} samples per cycle at "
             f"{p.freq:g} Hz; the landed height of each cycle (Fig. 1E, tau) needs at least 4: use --save-every "
             f"{1.0 / (4 * p.freq):g} or less, or --samples-per-cycle 8")


@dataclass(frozen=True)
class TauRule:
    """When a landed packing counts as entangled (:func:`tau_rule`).

    Attributes
    ----------
    height : float
        Smallest landed y_c / y_c(0).
    cluster : float
        Smallest largest-contact-cluster share f at the landing.
    """

    height: float
    cluster: float

    def describe(self) -> str:
        return (f"a cycle is entangled when, at its landing (the lowest centroid sample of the cycle), "
                f"y_c / y_c(0) >= {self.height:g} and f >= {self.cluster:g}; tau = entangled cycles / cycles shaken "
                f"(t_entangled / T), tau_first = cycles before the first one not entangled / cycles shaken")


def tau_rule(thresholds, height: float = TAU_HEIGHT) -> TauRule:
    """The paper's tau = t_entangled / T made a rule: a packing is entangled at a cycle's landing
    when it keeps its height (landed y_c / y_c(0) >= ``height``, :data:`TAU_HEIGHT`) and holds
    together (largest contact cluster share f >= the verdict's ``cluster``, 0.8). The paper shows
    the clump's centroid height (Fig. 1E, Fig. S1's raw data) and calls it entangled while it
    stands as one clump. In the closed container the rods of a collapsed packing still touch
    one another (f stayed 0.92-1.0 while the height fell from 1 to 0.25), so the height decides
    there; on an open plate the cluster does too, since a rod thrown off is lost to it
    (docs/experiments.md, "tau")."""
    return TauRule(height=height, cluster=thresholds.cluster)


def tau_series(entangled) -> dict:
    """tau (share of cycles entangled) and tau_first (share before the first cycle not
    entangled) of a per-cycle record."""
    e = np.asarray(entangled, dtype=bool)
    if e.size == 0:
        return {"tau": None, "tau_first": None}
    lost = np.flatnonzero(~e)
    first = int(lost[0]) if lost.size else e.size
    return {"tau": float(e.mean()), "tau_first": first / e.size}


def formation_events(cycles, f, entangled, rise: float = FORM_RISE, hold: int = FORM_CYCLES) -> list[dict]:
    """Entangled units that form during the shaking (Fig. 1E (i)): a cycle where the landed
    cluster share ``f`` first stands ``rise`` above its lowest value so far and stays there for
    ``hold`` cycles (``grows``), or where the packing, judged not entangled for ``hold`` cycles,
    is judged entangled for the next ``hold`` (``re-forms``)."""
    cycles, f, e = np.asarray(cycles), np.asarray(f, dtype=float), np.asarray(entangled, dtype=bool)
    out = []
    low = np.inf
    armed = True
    for i in range(len(f)):
        low = min(low, f[i])
        window = f[i:i + hold]
        if armed and len(window) == hold and np.all(window >= low + rise):
            out.append({"cycle": int(cycles[i]), "kind": "grows", "f_from": float(low), "f_to": float(window.min())})
            armed = False
            low = f[i]
        elif not armed and f[i] < low + rise / 2:
            armed = True
        if i >= hold and not e[i - hold:i].any() and len(e[i:i + hold]) == hold and e[i:i + hold].all():
            out.append({"cycle": int(cycles[i]), "kind": "re-forms"})
    return out


def excitation_shake(params, rows, t0: float, thresholds) -> dict:
    """The shaking's measures from the metrics rows (dicts as in metrics.csv) of a run whose
    shaking began at ``t0`` (s); a run still going gives the shaking so far (from its
    metrics.csv, written at each checkpoint).

    Returns
    -------
    dict
        :func:`~rodwarp.experiments.protocols.lab.shake_result` (y_c / y_c(0) at each sample and landed
        per cycle, the cohesion verdict) with the landed cluster share f and the entangled flag
        per cycle, ``tau`` (:func:`tau_rule`, :func:`tau_series`), ``formed``
        (:func:`formation_events`), ``landed_height_after_cycles`` (10, 50, 100, 500; None
        before), ``highest_rod_bottom_max_m`` and ``warnings``.
    """
    from rodwarp.experiments.protocols.lab import landed_samples, shake_result

    sh = shake_result(params, rows, t0, thresholds)
    shake = [r for r in _rows(rows, SHAKE) if float(r["time"]) > t0]
    t = np.array([float(r["time"]) for r in shake]) - t0
    y = np.asarray(sh["centroid_height_ratio"])
    f = np.array([float(r["largest_cluster_fraction"]) for r in shake])
    cyc, idx = landed_samples(t, y, params.freq)
    rule = tau_rule(thresholds)
    ent = (y[idx] >= rule.height) & (f[idx] >= rule.cluster)
    at = {}
    for n in (10, 50, 100, 500):
        k = np.flatnonzero(cyc == n)
        at[str(n)] = float(y[idx][k[0]]) if k.size else None
    top = np.array([float(r["highest_rod_bottom"]) for r in shake if r.get("highest_rod_bottom") not in ("", None)])
    sh["landed"].update({"largest_cluster_fraction": f[idx].tolist(), "entangled": ent.tolist()})
    sh["tau"] = {**tau_series(ent), "cycles": int(len(cyc)), "rule": rule.describe(),
                 "height": rule.height, "cluster": rule.cluster,
                 # how much the threshold matters: tau at the ends of TAU_HEIGHT_RANGE
                 "at_height": {f"{h:g}": tau_series((y[idx] >= h) & (f[idx] >= rule.cluster))["tau"]
                               for h in TAU_HEIGHT_RANGE}}
    sh["landed_height_after_cycles"] = at
    sh["formed"] = formation_events(cyc, f[idx], ent)
    sh["highest_rod_bottom_max_m"] = float(top.max()) if top.size else None
    sh["warnings"] = []
    if params.container_diameter > 0 and top.size and top.max() > params.container_height:
        sh["warnings"].append(f"a rod rose wholly above the container's {params.container_height * 1e3:g} mm rim "
                              f"({top.max() * 1e3:.0f} mm above the floor): in the laboratory it could have left "
                              f"the container (the model's wall is unbounded in height)")
    return sh


def _rows(rows, name):
    return [r for r in rows if r["stage"] == name]


def excitation_summary(params, model, rows, loop, stages, thresholds) -> tuple[str, dict]:
    """summary.json's ``excitation`` block: each parameter with its source, the scene, the pour
    (the packing's height and orientation in the tube), the release (height kept, spread), and
    the shaking: y_c(t) / y_c(0) at every sample and landed per cycle (Fig. 1E), the landed
    cluster share f, tau and tau_first (:func:`tau_rule`), entangled units formed
    (:func:`formation_events`), y_c / y_c(0) after 10, 50, 100 and 500 cycles, and the rim
    check (a rod above the container's rim would leave a real container)."""
    num = lambda r, k: None if r is None or r.get(k) in ("", None) else float(r[k])  # noqa: E731
    names = [s.name for s in stages]
    pour = _rows(rows, POUR)
    rt = params.pour_radius
    out = {"parameters": sources(params), "n_rods": model.n_rods, "stages": names,
           "container": "open plate" if params.container_diameter == 0 else
           f"cylinder {params.container_diameter * 1e3:g} mm across, shaken with the floor",
           "tube_radius_m": rt, "pour_height_m": params.pour_height(),
           "packing_volume_m3_at_phi_alpha_5.4": packing_volume(params),
           "pour": {"centroid_height_m": num(pour[-1], "centroid_height"),
                    "top_height_m": num(pour[-1], "top_height"),
                    "contacts_per_rod": num(pour[-1], "contacts_per_rod"),
                    "kinetic_energy_J": num(pour[-1], "kinetic_energy")}}
    warnings = []
    if RELEASE in names:
        i = names.index(RELEASE)
        before = _rows(rows, names[i - 1])[-1]
        rel = _rows(rows, RELEASE)
        out["release"] = {"height_kept": num(rel[-1], "centroid_height") / num(before, "centroid_height"),
                          "spread_radius_m": num(rel[-1], "spread_radius"),
                          "spread_over_tube": num(rel[-1], "spread_radius") / rt,
                          "largest_cluster_fraction": num(rel[-1], "largest_cluster_fraction"),
                          "kinetic_energy_J": num(rel[-1], "kinetic_energy")}
    if SHAKE in names:
        out["shake"] = excitation_shake(params, rows, loop.stage_t0[SHAKE], thresholds)
        warnings += out["shake"].pop("warnings")
    out["warnings"] = warnings
    return "excitation", out


class ExcitationProtocol(Protocol):
    """The excitation experiment as a protocol plug-in of :func:`rodwarp.experiments.run_protocol`."""

    name = "excitation"
    help = "the paper's excitation experiment, Fig. 1C-F: its rods, N, container and drive by default; docs/experiments.md"
    Params = ExcitationParams
    fields = (*EXCITATION_FIELDS, "pour_duration", "lift_duration")
    poured = True

    def resolve(self, params, explicit=None):
        return resolve_defaults(params, explicit)

    def plan(self, params):
        return excitation_plan(params)

    def packing(self, params, device):
        return excitation_packing(params, device)

    def walls(self, builder, params, rods):
        return excitation_walls(builder, params, rods)

    def check(self, p) -> None:
        check_excitation(p)

    def columns(self, model, x, control, t) -> dict:
        return excitation_columns(model, x, control, t)

    def summary(self, params, model, rows, loop, stages, thresholds):
        return excitation_summary(params, model, rows, loop, stages, thresholds)

    def rods(self, params) -> int:
        return rod_count(params)

    def pour_radius(self, params) -> float:
        """The inner tube's radius (m)."""
        return 0.5 * params.tube_diameter


EXCITATION = ExcitationProtocol()
