"""The protocol's parameters (:class:`ProtocolParams`, every default and help line stated once)
and the rod-model rule (:func:`rod_model_rule`). ``rodwarp simulate`` takes its options from
here (:func:`option_table`); :mod:`rodwarp.experiments._protocol` runs them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rodwarp._util import option, option_table  # noqa: F401 (option_table re-exported)

import numpy as np

#: rods per unit aspect ratio: the paper's packings hold N = round(5.4 alpha) rods (its
#: "Materials and Methods"; docs/protocol.md). A number of rods, not a contact number.
RODS_PER_ALPHA = 5.4
#: rigid rods when the self-weight sag of a simply supported rod, 5 q l^4 / (384 E I), is below
#: this fraction of a diameter (the knee of benchmarks/bench_rigid.py; docs/physics.md)
RIGID_SAG = 0.01


def _param(default, help: str, short: str | None = None):
    """A :class:`ProtocolParams` field: its default, its ``rodwarp simulate --help`` line, and
    its abbreviation in default folder names (:func:`default_run_name`; the name when None)."""
    return option(default, help, short=short)


@dataclass(frozen=True)
class ProtocolParams:
    """Parameters of :func:`run_protocol` (SI units; box in rod lengths), frozen.

    Every field's default and help text are stated here once; ``rodwarp simulate`` takes its
    options from them (:func:`option_table`). :meth:`validate` checks them and returns the
    parameters a run uses (:class:`~rodwarp.experiments.CheckedProtocol`); a variant is
    ``dataclasses.replace(params, ...)``.
    """

    alpha: float = _param(100.0, "Rod aspect ratio l / d (> 1).")
    freq: float = _param(10.0, "Floor vibration frequency of the stability test (Hz).")
    amplitude: float = _param(0.001, "Floor vibration amplitude of the stability test (m).", "amp")
    # the paper's rescaled gravity (docs/protocol.md, "Parameters and their rodwarp simulate options")
    gravity: float = _param(0.5, "Gravitational acceleration (m/s^2), rescaled as in the paper.")
    duration: float = _param(5.0, "Stability-test duration (s).", "dur")
    entangle_duration: float = _param(5.0, "Entangling duration (s); 0 skips entangling.", "edur")
    entangle_freq: float = _param(10.0, "Entangling vibration frequency (Hz).", "efreq")
    entangle_amplitude: float = _param(0.05, "Entangling vibration amplitude (m).", "eamp")
    static_load: float = _param(0.0, "Extra downward body load F~ in units of a rod's weight rho g d^2 l.", "F")
    n_rods: int | None = _param(None, f"Number of rods (default round({RODS_PER_ALPHA:g} alpha)).", "n")
    length: float = _param(1.0, "Rod length l (m).", "l")
    vertices: int = _param(10, "Vertices per rod.", "v")
    box: tuple = _param((1.0, 1.0, 2.5), "Container size in rod lengths, 'X,Y,Z'.")
    mu: float = _param(0.2, "Friction coefficient (rod-rod and walls).")
    young: float = _param(200e9, "Young's modulus (Pa).", "E")
    density: float = _param(7850.0, "Density (kg/m^3).", "rho")
    dt: float | None = _param(None, "Time step (s); default from the scene's step bound.")
    iterations: int = _param(10, "Most Gauss-Seidel sweeps per step (10: the knee of the effort benchmark).",
                                 "it")
    rod_model: str = _param("auto", f"auto (rigid when the rods' self-weight sag is below {RIGID_SAG:g} d), rigid "
                                    "or elastic.")
    step_safety: float = _param(1.0, "Adaptive step: the fastest rod crosses at most this many diameters per step "
                                     "(1: the knee of the effort benchmark; the step also shrinks while rods "
                                     "overlap by more than 0.02 d; ignored with --dt).")
    rolling: bool | None = _param(None, "Rods spin about their axes; --no-rolling locks the spin (friction on the "
                                        "centreline only). Default: on with the exact contact law, off with IMC "
                                        "(DisMech's friction acts on the centreline).")
    contact_law: str | None = _param(None, "Contact law: exact (Signorini and the Coulomb cone, the default) or imc "
                                           "(DisMech's smooth penalty and smoothed friction, the paper's; "
                                           "docs/physics.md).", "law")
    imc_delta: float | None = _param(None, "IMC distance tolerance delta, in rod diameters (default 0.1: the "
                                           "paper's d/10).", "delta")
    imc_nu: float | None = _param(None, "IMC slip tolerance nu (m/s; default 1e-3, DisMech's examples): friction "
                                        "is smoothed below it, so a load below mu F_n creeps.", "nu")
    imc_stiffness: float | None = _param(None, "IMC contact stiffness k_c (N/m; default 1000 rod weights per "
                                               "delta).", "kc")
    save_every: float = _param(0.1, "Metrics and frame interval (s of simulated time).", "save")
    checkpoint_every: float = _param(1.0, "Checkpoint interval (s of simulated time).", "ckpt")
    fields_every: float = _param(0.5, "Interval (s of simulated time, a multiple of --save-every) of the "
                                      "entanglement fields during the run: cv_e(t), mean e and phi in "
                                      "metrics.csv; 0 turns them off.", "fev")
    seed: int = _param(0, "Random seed of the packing.")
    device: str = _param("auto", "auto, cpu or cuda.")
    initial: str | None = _param(None, "Start from this rod set (npz, zarr or CSV) instead of a random packing.")
    # a CSV does not record its unit: without this it is read as metres (the simulation runs in SI)
    units: str | None = _param(None, "Length unit of a CSV --initial rod set: m (the default), mm or um; "
                                     "converted to metres. An npz/zarr records its own.")
    initial_diameter: float | None = _param(None, "Rod diameter (in --units) for a CSV --initial rod set without a "
                                                  "radius column.", "d")
    entangle: bool = _param(False, "With --initial: run the entangling stage too.")

    def validate(self, explicit=()):
        """Raise :class:`RodwarpError` (one line) for any impossible, inconsistent or oversized
        parameter, before any work (:func:`rodwarp.experiments.check_protocol`).

        Parameters
        ----------
        explicit : iterable of str
            Field names of the options the user gave (an --alpha that contradicts an
            ``initial`` rod set is refused only when given).

        Returns
        -------
        CheckedProtocol
            The parameters a run uses (with ``initial``: alpha and length from the input
            rods, which it holds loaded and in metres), unchanged otherwise.
        """
        from rodwarp.experiments._checks import check_protocol

        return check_protocol(self, explicit)

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
    def diameter(self) -> float:
        """Rod diameter d = l / alpha (m)."""
        return self.length / self.alpha

    @property
    def rods(self) -> int:
        """Number of rods: ``n_rods``, else round(5.4 alpha)."""
        return self.n_rods if self.n_rods is not None else int(round(RODS_PER_ALPHA * self.alpha))

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
    d = params.diameter
    r = d / 2
    g_eff = params.effective_gravity
    q = params.density * math.pi * r**2 * g_eff
    EI = params.young * math.pi * r**4 / 4
    sag = 5 * q * params.length**4 / (384 * EI) / d
    choice = params.rod_model
    if choice == "auto":
        choice = "rigid" if sag < RIGID_SAG else "elastic"
    return {"rod_model": choice, "requested": params.rod_model, "sag_over_d": sag, "threshold": RIGID_SAG,
            "rule": f"rigid when the self-weight sag 5 q l^4 / (384 E I) < {RIGID_SAG:g} d, else elastic"}
