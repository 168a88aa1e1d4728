"""A run's parameters, :class:`ProtocolParams`: the flat record of :class:`ExperimentParams`,
every registered protocol's own parameters and :class:`RunParams` (each field's default and
help line stated once, in the dataclass that owns it), with what they imply: the rod-model rule
(:func:`rod_model_rule`), the resolution rule (:func:`rod_resolution`) and the default folder
name. ``rodwarp simulate`` takes its options from here (:func:`option_table`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from rodwarp._util import option_table  # noqa: F401 (option_table re-exported)
from rodwarp.experiments._fields import (MAX_VERTICES, MIN_VERTICES, POUR_PHI_ALPHA, QUASI_STATIC,  # noqa: F401
                                         RIGID_SAG, RODS_PER_ALPHA, ExperimentParams, RunParams)


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
            return ContactLaw("exact", restitution=self.restitution or 0.0)
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
    from rodwarp.experiments.protocols import plan

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
               "restitution", "save_every", "checkpoint_every", "fields_every", "seed", "device", "initial", "units",
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
