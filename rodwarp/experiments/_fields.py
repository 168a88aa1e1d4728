"""What every protocol shares: :class:`ExperimentParams` (the rods, their material, gravity,
the test's drive) and :class:`RunParams` (how a run steps and records), with the constants
their defaults and help lines state. Each protocol adds its own parameters
(:mod:`rodwarp.experiments.protocols`); :class:`~rodwarp.experiments.ProtocolParams` is the
flat record of all of them.
"""

from __future__ import annotations

from dataclasses import dataclass

from rodwarp.experiments._option import param as _param
from rodwarp.validation import MAX_MU, Range

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
    cycles: float | None = _param(None, "Stability-test length in drive cycles: sets --duration to cycles / --freq "
                                        "(tests of equal cycles compare drives of different frequency).", "cyc",
          range=Range(gt=0, le=1e6, hint="a number of drive periods; the duration follows from --freq"))
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
    restitution: float | None = _param(None, "Coefficient of restitution e of the exact contact law (0: perfectly "
                                             "inelastic, the default; e > 0: a contact approaching faster than "
                                             "max(2 g dt, 1 mm/s) leaves at e times its approach speed; "
                                             "docs/physics.md, 'Restitution'). Not with --contact-law imc.", "e",
          range=Range(ge=0, le=1, hint="e is 0 (perfectly inelastic) to 1 (elastic)"))
    save_every: float = _param(0.1, "Metrics and frame interval (s of simulated time).", "save",
          range=Range(gt=0, le=1e5, unit="s"))
    checkpoint_every: float = _param(1.0, "Checkpoint interval (s of simulated time).", "ckpt",
          range=Range(gt=0, le=1e5, unit="s"))
    samples_per_cycle: int | None = _param(None, "Samples per drive cycle during the stability test (replaces "
                                                 "--save-every there); 4 or more give the landed measures: h and f "
                                                 "at the lowest centroid of each cycle (docs/verdict.md).", "spc",
          range=Range(ge=1, le=1000, whole=True, hint="samples per drive period of the test; 8 resolves the landing"))
    fields_every: float = _param(0.5, "Interval (s of simulated time, a multiple of --save-every) of the "
                                      "entanglement fields during the run: cv_e(t), mean e and phi in "
                                      "metrics.csv; 0 turns them off.", "fev",
          range=Range(ge=0, le=1e5, unit="s", hint="0 turns the fields series off"))
    seed: int = _param(0, "Random seed of the packing.",
          range=Range(ge=0, le=2**63 - 1, whole=True))
    device: str = _param("auto", "auto, cpu or cuda.")
