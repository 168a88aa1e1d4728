"""The protocol's parameters (:class:`ProtocolParams`, every default and help line stated once)
and the rod-model rule (:func:`rod_model_rule`). ``rodwarp simulate`` takes its options from
here (:func:`option_table`); :mod:`rodwarp.experiments._protocol` runs them.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from rodwarp._util import option_table  # noqa: F401 (option_table re-exported)
from rodwarp.experiments._option import param as _param
from rodwarp.validation import MAX_MU, Range

import numpy as np

#: rods per unit aspect ratio: the paper's packings hold N = round(5.4 alpha) rods (its
#: "Materials and Methods"; docs/protocol.md). A number of rods, not a contact number.
RODS_PER_ALPHA = 5.4
#: the pour: rods released in a column above the floor at this phi alpha (dilute: they fall freely)
POUR_PHI_ALPHA = 2.0
#: rigid rods when the self-weight sag of a simply supported rod, 5 q l^4 / (384 E I), is below
#: this fraction of a diameter (the knee of benchmarks/bench_rigid.py; docs/physics.md)
RIGID_SAG = 0.01
#: elastic rods' resolution (:func:`rod_resolution`): the fewest and the most vertices the rule
#: picks
MIN_VERTICES, MAX_VERTICES = 3, 10
#: a drive is quasi-static for the rods' bending when its frequency is below this fraction of
#: their first free-free bending frequency (the static response is then amplified by under 1%)
QUASI_STATIC = 0.1


#: the strongest drive accepted, peak acceleration over gravity: the paper's entangling drive is
#: a/g ~ 400 at its rescaled gravity (5 cm at 10 Hz, g 0.5), its tests 0.3 to 7.9; beyond 1000 a
#: drive is a typo or a shock, and it tears any packing apart
MAX_A_OVER_G = 1000.0
#: the widest plate stroke of a poured packing, in rod lengths: the alpha* study's largest drive
#: is l / 2; a plate swinging more than two rod lengths throws rods out of any container
MAX_PLATE_AMPLITUDE_LENGTHS = 2.0
#: the IMC stiffness accepted, in heaviest-rod weights per delta: the default is 1000 and DisMech's
#: floor about 100; below 1 a rod's own weight pushes it through delta, above 1e6 the penalty is a
#: rigid wall (a 20-weight contact overlaps 2e-5 delta), outside the range docs/physics.md checks
#: its implicit solve in; the exact law is the rigid one
IMC_STIFFNESS_WEIGHTS_RANGE = (1.0, 1e6)


@dataclass(frozen=True)
class ExperimentParams:
    """What every protocol shares (SI units): the protocol, the rods, their material, gravity,
    and the test's drive and duration. Frozen; each protocol adds its own parameters
    (:mod:`rodwarp.experiments.protocols`) and every run :class:`RunParams`."""

    protocol: str = _param("paper", "paper (random packing in a box, entangling, the vibration test; "
                                    "docs/protocol.md) or lab (rods poured into a cylinder, pressed by a piston to "
                                    "--strains, the cylinder lifted away, the plate shaken at --freq, --amplitude "
                                    "for --duration; docs/experiments.md) or excitation (the paper's excitation experiment, Fig. 1C-F: its "
                                    "rods, N, container and drive by default; docs/experiments.md).", "proto")
    alpha: float = _param(100.0, "Rod aspect ratio l / d (> 1).",
          range=Range(gt=1, le=1e4, hint="alpha is rod length over diameter; the paper spans 5 to 333, felts reach 1e3"))
    freq: float = _param(10.0, "Floor vibration frequency of the stability test (Hz).",
          range=Range(ge=0, le=1000, unit="Hz", hint="a vibration, not an acoustic wave: the paper drives at 1 to 100 Hz"))
    amplitude: float = _param(0.001, "Floor vibration amplitude of the stability test (m).", "amp",
          range=Range(ge=0, le=100, unit="m", hint="the stroke is also checked against the box and the rods"))
    # the paper's rescaled gravity (docs/protocol.md, "Parameters and their rodwarp simulate options")
    gravity: float = _param(0.5, "Gravitational acceleration (m/s^2), rescaled as in the paper.",
          range=Range(ge=1e-3, le=1000, unit="m/s^2", hint="the paper rescales g to 0.5; 1000 is 100 Earth g"))
    duration: float = _param(5.0, "Stability-test duration (s).", "dur",
          range=Range(ge=0, le=1e5, unit="s", hint="the run's step count is checked as well"))
    static_load: float = _param(0.0, "Extra downward body load F~ in units of a rod's weight rho g d^2 l.", "F",
          range=Range(ge=0, le=1e4, hint="in units of a rod's weight rho g d^2 l (the paper's F~ is 0 to 12)"))
    n_rods: int | None = _param(None, f"Number of rods (default round({RODS_PER_ALPHA:g} alpha); lab: the rods "
                                      "that fill the cylinder to --fill-height; excitation: the paper's 1.25e6 / (d l^2), "
                                      "d and l in mm).", "n",
          range=Range(ge=1, le=1e8, whole=True, hint="memory and time are checked as well"))
    length: float = _param(1.0, "Rod length l (m).", "l",
          range=Range(ge=1e-5, le=100, unit="m", hint="rods shorter than 10 um feel forces rodwarp does not model (adhesion, Brownian motion); the paper's are 25 to 50 mm, its simulations 1 m"))
    vertices: int | None = _param(None, f"Vertices per elastic rod (default: the resolution rule, {MIN_VERTICES}-"
                                        f"{MAX_VERTICES}: the fewest whose self-weight sag is within {RIGID_SAG:g} d "
                                        f"of the beam's where every drive is quasi-static, else {MAX_VERTICES}; "
                                        "docs/physics.md).", "v",
          range=Range(ge=2, le=10_000, whole=True))
    mu: float = _param(0.2, "Friction coefficient (rod-rod and walls).",
          range=Range(ge=0, le=MAX_MU, hint="friction coefficients of real materials are below about 2 (steel on steel 0.2 to 0.8, rubber up to about 2)"))
    young: float = _param(200e9, "Young's modulus (Pa).", "E",
          range=Range(ge=1e3, le=1e13, unit="Pa", hint="from soft gels (1 kPa) to diamond (1.2e12 Pa)"))
    density: float = _param(7850.0, "Density (kg/m^3).", "rho",
          range=Range(ge=1, le=1e5, unit="kg/m^3", hint="from aerogels to osmium (22600 kg/m^3)"))


@dataclass(frozen=True)
class RunParams:
    """How a run steps and records, whatever the protocol: the step and its effort, the rod
    model and the contact law, the sampling, checkpoints, seed and device. Frozen."""

    dt: float | None = _param(None, "Time step (s); default from the scene's step bound.",
          range=Range(gt=0, le=1, unit="s", hint="leave it out for the default step"))
    iterations: int = _param(10, "Most Gauss-Seidel sweeps per step (10: the knee of the effort benchmark).",
                                 "it",
          range=Range(ge=1, le=100_000, whole=True))
    rod_model: str = _param("auto", f"auto (rigid when the rods' self-weight sag is below {RIGID_SAG:g} d), rigid "
                                    "or elastic.")
    step_safety: float = _param(2.0, "Adaptive step: the fastest rod crosses at most this many diameters per step "
                                     "(2: the knee of the effort benchmark; the step also shrinks while rods "
                                     "overlap by more than 0.02 d; ignored with --dt).",
          range=Range(gt=0, le=4, hint="the fraction of a diameter the fastest rod may cross per step"))
    steps_per_period: float = _param(20.0, "Adaptive step: the fewest steps per period of a drive (20: the knee "
                                           "of the effort benchmark; ignored with --dt).", "spp",
          range=Range(ge=4, le=1000, hint="the fewest steps per drive period"))
    rolling: bool | None = _param(None, "Rods spin about their axes; --no-rolling locks the spin (friction on the "
                                        "centreline only). Default: on with the exact contact law, off with IMC "
                                        "(DisMech's friction acts on the centreline).")
    contact_law: str | None = _param(None, "Contact law: exact (Signorini and the Coulomb cone, the default) or imc "
                                           "(DisMech's smooth penalty and smoothed friction, the paper's; "
                                           "docs/physics.md).", "law")
    imc_delta: float | None = _param(None, "IMC distance tolerance delta, in rod diameters (default 0.1: the "
                                           "paper's d/10).", "delta",
          range=Range(ge=0.01, le=1, hint="delta is in rod diameters (the paper's d/10 is 0.1); below 0.01 d the penalty is sharper than the solver resolves (it lets rods overlap by 0.02 d)"))
    imc_nu: float | None = _param(None, "IMC slip tolerance nu (m/s; default 1e-3, DisMech's examples): friction "
                                        "is smoothed below it, so a load below mu F_n creeps.", "nu",
          range=Range(ge=1e-6, le=10, unit="m/s", hint="the slip tolerance is a speed (DisMech's examples use 1e-3 m/s)"))
    imc_stiffness: float | None = _param(None, "IMC contact stiffness k_c (N/m; default 1000 rod weights per "
                                               "delta).", "kc",
          range=Range(gt=0, le=1e15, unit="N/m", hint="also checked in rod weights per delta; leave it out for 1000 rod weights per delta"))
    save_every: float = _param(0.1, "Metrics and frame interval (s of simulated time).", "save",
          range=Range(gt=0, le=1e5, unit="s"))
    checkpoint_every: float = _param(1.0, "Checkpoint interval (s of simulated time).", "ckpt",
          range=Range(gt=0, le=1e5, unit="s"))
    fields_every: float = _param(0.5, "Interval (s of simulated time, a multiple of --save-every) of the "
                                      "entanglement fields during the run: cv_e(t), mean e and phi in "
                                      "metrics.csv; 0 turns them off.", "fev",
          range=Range(ge=0, le=1e5, unit="s", hint="0 turns the fields series off"))
    seed: int = _param(0, "Random seed of the packing.",
          range=Range(ge=0, le=2**63 - 1, whole=True))
    device: str = _param("auto", "auto, cpu or cuda.")


class _Derived:
    """What :class:`ProtocolParams` derives from its fields: the checks, the rod count and
    resolution, the contact law object, the drive's strength."""

    def validate(self, explicit=None):
        """Raise :class:`RodwarpError` (one line) for any impossible, inconsistent or oversized
        parameter, before any work (:func:`rodwarp.experiments.check_protocol`).

        Parameters
        ----------
        explicit : iterable of str or None
            Field names of the options the user gave (an --alpha that contradicts an
            ``initial`` rod set is refused only when given; the excitation protocol takes the
            paper's values for the others). None: those that differ from the defaults here.

        Returns
        -------
        CheckedProtocol
            The parameters a run uses (with ``initial``: alpha and length from the input
            rods, which it holds loaded and in metres), unchanged otherwise.
        """
        from rodwarp.experiments._checks import check_protocol

        return check_protocol(self, explicit)

    @property
    def run_params(self) -> RunParams:
        """The run's :class:`RunParams` (step, sampling, model, contact law, seed, device)."""
        return RunParams(**{f.name: getattr(self, f.name) for f in fields(RunParams)})

    @property
    def law(self) -> str:
        """The contact law, ``exact`` unless ``contact_law`` says ``imc``."""
        return self.contact_law or "exact"

    @property
    def spin(self) -> bool:
        """Whether rods spin: ``rolling``, else on with the exact law and off with IMC."""
        return self.rolling if self.rolling is not None else self.law != "imc"

    def contact_law_object(self):
        """The :class:`~rodwarp.sim.ContactLaw` of these parameters (delta still in diameters
        here is converted to metres)."""
        from rodwarp.sim.contact_law import IMC_NU, ContactLaw

        if self.law != "imc":
            return ContactLaw("exact")
        delta = None if self.imc_delta is None else self.imc_delta * self.diameter
        return ContactLaw("imc", delta=delta, nu=self.imc_nu if self.imc_nu is not None else IMC_NU,
                          stiffness=self.imc_stiffness)

    @property
    def n_vertices(self) -> int:
        """Vertices per rod of the packing: ``vertices``; else, for elastic rods, the resolution
        rule's (:func:`rod_resolution`), and for rigid rods ``MAX_VERTICES`` (the packing's
        polylines; the model holds each as two vertices)."""
        if self.vertices is not None:
            return int(self.vertices)
        if rod_model_rule(self)["rod_model"] == "rigid":
            return MAX_VERTICES
        return rod_resolution(self)["vertices"]

    @property
    def diameter(self) -> float:
        """Rod diameter d = l / alpha (m)."""
        return self.length / self.alpha

    @property
    def rods(self) -> int:
        """Number of rods: ``n_rods``, else round(5.4 alpha) (lab: the rods that fill its cylinder;
        excitation: the paper's N = 1.25e6 / (d l^2), d and l in mm)."""
        if self.n_rods is not None:
            return self.n_rods
        from rodwarp.experiments.protocols import protocol

        return protocol(self.protocol).rods(self)

    @property
    def pour_radius(self) -> float:
        """Radius (m) of the cylinder the rods are poured into: the lab's container
        (``container_radius`` rod lengths), the excitation experiment's tube."""
        from rodwarp.experiments.protocols import protocol

        return protocol(self.protocol).pour_radius(self)

    def pour_height(self) -> float:
        """Height (m) of the column the poured rods are released in: they take it at phi alpha =
        2 (dilute, so they fall freely), and at least 1.2 rod lengths."""
        rc = self.pour_radius
        v_rod = math.pi / 4 * self.diameter**2 * self.length
        return max(1.2 * self.length, self.rods * v_rod / (POUR_PHI_ALPHA / self.alpha * math.pi * rc**2))

    @property
    def a_over_g(self) -> float:
        """Peak floor acceleration over gravity, a/g = 4 pi^2 f^2 A / g (dimensionless)."""
        return 4 * math.pi**2 * self.freq**2 * self.amplitude / self.gravity

    @property
    def effective_gravity(self) -> float:
        """Gravity with the static load as an extra body load, g (1 + 4 F~ / pi) (m/s^2;
        docs/protocol.md, "The experiment")."""
        return self.gravity * (1.0 + 4.0 * self.static_load / math.pi)

def _straight(rods, tol: float = 1e-3) -> bool:
    """Every rod's vertices (and rest vertices) lie within ``tol`` radii of its chord."""
    for pts in (rods.points, rods.rest_points):
        if pts is None:
            continue
        off = rods.offsets
        rid = np.repeat(np.arange(rods.n_rods), np.diff(off))
        p0, p1 = pts[off[:-1]], pts[off[1:] - 1]
        chord = p1 - p0
        dev = np.linalg.norm(np.cross(pts - p0[rid], chord[rid]), axis=1) / np.linalg.norm(chord, axis=1)[rid]
        if np.any(dev > tol * rods.radii[rid]):
            return False
    return True


def rod_model_rule(params: ProtocolParams) -> dict:
    """Which rod model the experiment uses and why.

    ``auto`` picks rigid rods when their bending under the scene's largest static load, the
    self-weight sag 5 q l^4 / (384 E I) of a simply supported rod with q = rho A g_eff
    (static load included), is below ``RIGID_SAG`` diameters; elastic otherwise, and always
    for an input with curved rods (rigid rods must be straight).

    Returns
    -------
    dict
        ``rod_model`` (the choice), ``requested``, ``sag_over_d``, ``threshold`` and ``rule``.
    """
    sag = _sag_over_d(params)
    choice = params.rod_model
    if choice == "auto":
        choice = "rigid" if sag < RIGID_SAG else "elastic"
    return {"rod_model": choice, "requested": params.rod_model, "sag_over_d": sag, "threshold": RIGID_SAG,
            "rule": f"rigid when the self-weight sag 5 q l^4 / (384 E I) < {RIGID_SAG:g} d, else elastic"}


def discrete_sag(n: int) -> np.ndarray:
    """Deflection of a simply supported rod under its own weight discretised with ``n`` equal
    edges' vertices (rodwarp's bending energy E I |kappa_i|^2 / (2 l_i) with its linear
    curvature, lumped masses, the end vertices on the supports), in units of q l^4 / (E I),
    at the vertices: the static solution of the discrete model, one small linear solve."""
    n = int(n)
    w = np.zeros(n)
    if n < 3:
        return w  # a two-vertex rod does not bend
    h = 1.0 / (n - 1)
    D = np.zeros((n - 2, n))
    for i in range(n - 2):
        D[i, i:i + 3] = (1.0, -2.0, 1.0)  # kappa_i h at interior vertex i
    K = D.T @ D / h**3  # E I = l = 1
    f = np.full(n, h)  # lumped weights of a unit load per length
    f[[0, -1]] = h / 2
    w[1:-1] = np.linalg.solve(K[1:-1, 1:-1], f[1:-1])
    return w


def beam_sag(s) -> np.ndarray:
    """Euler-Bernoulli deflection of a simply supported beam under a uniform load at the
    fractions ``s`` of its length, in units of q l^4 / (E I): (s - 2 s^3 + s^4) / 24."""
    s = np.asarray(s, dtype=float)
    return (s - 2 * s**3 + s**4) / 24.0


def sag_discretisation_error(n: int) -> float:
    """Largest error of the discrete self-weight sag (:func:`discrete_sag`) over the vertices,
    as a fraction of the beam's midspan sag 5 q l^4 / (384 E I): 0.20 at 3 vertices, 0.079 at
    4, 0.031 at 6, 0.0098 at 10 (second order in the edge length); 1 for a straight two-vertex rod."""
    if int(n) < 3:
        return 1.0
    return float(np.abs(discrete_sag(n) - beam_sag(np.linspace(0.0, 1.0, int(n)))).max() / (5.0 / 384.0))


def first_bending_frequency(params: ProtocolParams) -> float:
    """First free-free bending frequency of a rod (Hz): (4.730^2 / (2 pi l^2)) sqrt(E I / (rho A))."""
    r = params.diameter / 2
    return 4.730**2 / (2 * math.pi * params.length**2) * math.sqrt(params.young * r * r / 4 / params.density)


def rod_resolution(params: ProtocolParams, sag_over_d: float | None = None) -> dict:
    """How many vertices an elastic rod needs in this experiment, and why (docs/physics.md,
    "Resolution of elastic rods").

    Where every drive of the run is quasi-static for the rods' bending (its frequency below
    ``QUASI_STATIC`` of their first bending frequency), their deflection is the static response
    to the loads they carry, and the rule takes the fewest vertices (at least ``MIN_VERTICES``)
    whose discrete self-weight sag is within ``RIGID_SAG`` diameters of the beam's
    (:func:`sag_discretisation_error` x sag <= ``RIGID_SAG`` d: the tolerance of the rigid rule,
    which accepts an error of the whole sag), at most ``MAX_VERTICES``. Where a drive reaches the
    bending modes, ``MAX_VERTICES``. An explicit ``vertices`` wins.

    Returns
    -------
    dict
        ``vertices``, ``requested`` (the option, None for the rule), ``first_bending_hz``,
        ``drive_hz`` (the fastest drive), ``quasi_static``, ``sag_error_over_d`` (the discrete
        sag's error at the chosen resolution, in diameters) and ``rule``.
    """
    if sag_over_d is None:
        sag_over_d = _sag_over_d(params)
    f1 = first_bending_frequency(params)
    from rodwarp.experiments._plan import plan

    drive = max((s.freq for s in plan(params) if s.duration > 0), default=0.0)
    quasi = drive <= QUASI_STATIC * f1
    n = MAX_VERTICES
    if quasi:
        n = next((k for k in range(MIN_VERTICES, MAX_VERTICES + 1)
                  if sag_discretisation_error(k) * sag_over_d <= RIGID_SAG), MAX_VERTICES)
    chosen = int(params.vertices) if params.vertices is not None else n
    return {"vertices": chosen, "requested": params.vertices, "first_bending_hz": f1, "drive_hz": drive,
            "quasi_static": bool(quasi), "sag_error_over_d": sag_discretisation_error(chosen) * sag_over_d,
            "rule": (f"elastic rods: the fewest vertices ({MIN_VERTICES}-{MAX_VERTICES}) whose self-weight sag is "
                     f"within {RIGID_SAG:g} d of the beam's when every drive is below {QUASI_STATIC:g} of the first "
                     f"bending frequency, else {MAX_VERTICES}")}


def _sag_over_d(params: ProtocolParams) -> float:
    """Self-weight sag of a simply supported rod, 5 q l^4 / (384 E I), in diameters: the midspan
    deflection of a rod resting on its two ends under its own weight q = rho A g_eff (static load
    included). The one sag every rule and doc uses (not a cantilever's q l^4 / (8 E I), 9.6 times
    as much): 0.032 d for the laboratory's alpha-200 steel rods (l 50 mm, d 0.25 mm, g 9.81 m/s^2;
    tests/test_sag.py)."""
    d = params.diameter
    r = d / 2
    q = params.density * math.pi * r**2 * params.effective_gravity
    EI = params.young * math.pi * r**4 / 4
    return 5 * q * params.length**4 / (384 * EI) / d


#: the order default folder names list non-default parameters in (the order of the options before
#: they were grouped by protocol; a parameter not listed comes after, in field order)
_NAME_ORDER = ("protocol", "alpha", "freq", "amplitude", "gravity", "duration", "entangle_duration", "entangle_freq",
               "entangle_amplitude", "static_load", "n_rods", "length", "vertices", "box", "container_radius",
               "fill_height", "container_diameter", "container_height", "tube_diameter", "pour_duration", "strains",
               "press_duration", "lift_duration", "mu", "wall_mu", "young", "density", "dt", "iterations", "rod_model",
               "step_safety", "steps_per_period", "rolling", "contact_law", "imc_delta", "imc_nu", "imc_stiffness",
               "save_every", "checkpoint_every", "fields_every", "seed", "device", "initial", "units",
               "initial_diameter", "entangle")


def default_run_name(params: ProtocolParams) -> str:
    """Default simulate folder name: alpha, freq, gravity and seed always, then every other
    parameter that differs from its default (``key<value>``, the key abbreviated as the
    field's ``short`` metadata says), so that runs differing in any parameter never share a
    folder; a short hash stands in for a list that would be too long."""
    import hashlib

    d = asdict(params)
    defaults = {f.name: f.default for f in fields(ProtocolParams)}
    short = {f.name: f.metadata.get("short") or f.name for f in fields(ProtocolParams)}

    def fmt(v):
        if isinstance(v, float):
            return f"{v:g}"
        if isinstance(v, (tuple, list)):
            return "x".join(fmt(x) for x in v)
        return str(v)

    if params.initial:
        head = f"{Path(params.initial).stem}_freq{fmt(params.freq)}_g{fmt(params.gravity)}"
        skip = {"freq", "gravity", "initial", "device", "alpha", "length", "seed", "fields_every"}
    else:
        head = f"alpha{fmt(params.alpha)}_freq{fmt(params.freq)}_g{fmt(params.gravity)}_seed{params.seed}"
        skip = {"alpha", "freq", "gravity", "seed", "device", "initial", "fields_every"}

    def differs(k, v):
        dv = defaults.get(k)
        if isinstance(v, (tuple, list)) and isinstance(dv, (tuple, list)):
            return list(v) != list(dv)
        return v != dv

    # the parameters in the order folder names have always listed them (new ones after), so a
    # run's default folder keeps its name however the dataclasses group their fields
    rank = {k: i for i, k in enumerate(_NAME_ORDER)}
    keys = sorted(d, key=lambda k: rank.get(k, len(rank)))
    extra = [f"{short[k]}{fmt(d[k])}" for k in keys if k not in skip and differs(k, d[k])]
    name = "_".join([head, *extra])
    if len(name) > 120:
        name = head + "_" + hashlib.sha1("_".join(extra).encode()).hexdigest()[:10]
    return name.replace("/", "-")


def _compose():
    """:class:`ProtocolParams`: the fields of :class:`ExperimentParams`, of every registered
    protocol's own parameters (``Protocol.Params``, in the registry's order) and of
    :class:`RunParams`, with :class:`_Derived`'s methods; frozen."""
    from dataclasses import field, make_dataclass

    from rodwarp.experiments.protocols import PROTOCOLS

    groups = [ExperimentParams, *dict.fromkeys(p.Params for p in PROTOCOLS.values() if p.Params is not None),
              RunParams]
    specs, seen = [], set()
    for group in groups:
        hints = group.__annotations__
        for f in fields(group):
            if f.name in seen:
                raise TypeError(f"parameter {f.name} is declared twice ({group.__name__})")
            seen.add(f.name)
            meta = dict(f.metadata)
            if f.name == "protocol":  # the choices and what each does, from the registry
                meta["help"] = " or ".join(f"{p.name} ({p.help})" for p in PROTOCOLS.values()) + "."
            specs.append((f.name, hints[f.name], field(default=f.default, metadata=meta)))
    cls = make_dataclass("ProtocolParams", specs, bases=(_Derived,), frozen=True)
    cls.__module__ = __name__
    cls.__doc__ = _DOC
    return cls


_DOC = """Parameters of :func:`run_protocol` (SI units; box in rod lengths), frozen: one flat record of
:class:`ExperimentParams`, each protocol's own parameters and :class:`RunParams`.

Every field's default and help text are stated once, in the dataclass that owns it;
``rodwarp simulate`` takes its options from them (:func:`option_table`), in this order.
:meth:`validate` checks them and returns the parameters a run uses
(:class:`~rodwarp.experiments.CheckedProtocol`); a variant is ``dataclasses.replace(params, ...)``.
"""

ProtocolParams = _compose()
