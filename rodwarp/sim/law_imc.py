"""The IMC contact law (host side): DisMech's incremental potential contact.

A smooth penalty within a distance tolerance delta of touching and friction smoothed below a
slip tolerance nu, on the centreline (docs/physics.md, "The IMC contact law"). Device
functions: :mod:`rodwarp.kernels.imc`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rodwarp.arguments import real
from rodwarp.errors import RodwarpError
from rodwarp.kernels import imc
from rodwarp.sim._limits import MAX_LENGTH_M, MAX_SPEED
from rodwarp.sim._law import ContactLaw

#: IMC's K1 = 15 / delta and K2 = 15 / nu (DisMech's contact_force.cpp and floor_contact_force.cpp)
IMC_SHARPNESS = 15.0
#: default distance tolerance delta in diameters of the thinnest rod: the paper's "contact
#: tolerance d/10" (its Materials and Methods)
IMC_DELTA_DIAMETERS = 0.1
#: default slip tolerance nu (m/s). DisMech's examples use 1e-3 m/s (its README and
#: examples' "nu"); the paper does not state its value
IMC_NU = 1e-3
#: default contact stiffness k_c in units of the heaviest rod's weight per delta: stiff enough
#: that a contact carrying 20 rod weights overlaps by 1% of delta beyond the law's smoothing, and
#: an impact at 3 m/s on l = 1 m steel rods stays within 0.7 delta (k_c = 1000 m g / delta;
#: DisMech's floor, 1e4 N/m for gram-scale rods with delta ~ 0.1 mm, sits at about 100 m g / delta)
IMC_STIFFNESS_WEIGHTS = 1000.0
#: stiffest contact accepted (N/m): a steel bar of 1 m^2 section and 0.2 mm length, far beyond
#: any contact between rods
IMC_MAX_STIFFNESS = 1e15


@dataclass(frozen=True)
class ImcLaw(ContactLaw):
    """DisMech's IMC law.

    Parameters
    ----------
    delta : float, optional
        Distance tolerance (m, in (0, 1e6]): the penalty acts at surface gaps below it.
        Default ``IMC_DELTA_DIAMETERS`` (0.1) diameters of the thinnest rod.
    nu : float
        Slip tolerance (m/s, in (0, 1e3]): friction is full Coulomb above it and smoothed
        below it.
    stiffness : float, optional
        Contact stiffness k_c (N/m, in (0, ``IMC_MAX_STIFFNESS``]) of the energy
        k_c [softplus(-K1 g) / K1]^2. Default ``IMC_STIFFNESS_WEIGHTS`` heaviest-rod weights
        per delta (gravity's magnitude, 9.81 m/s^2 without gravity).
    """

    name = "imc"
    device = imc
    projects_overlaps = False  # the penalty's overlap is its compliance

    delta: float | None = None
    nu: float = IMC_NU
    stiffness: float | None = None

    def __post_init__(self):
        for what, value, top, unit in (("delta", self.delta, MAX_LENGTH_M, "m"), ("nu", self.nu, MAX_SPEED, "m/s"),
                                       ("stiffness", self.stiffness, IMC_MAX_STIFFNESS, "N/m")):
            if value is not None and not real(what, value, le=top, unit=unit, hint=f"the IMC {what}") > 0:
                raise RodwarpError(f"{what} must be a positive number ({unit}), the IMC {what}, got {value:g}")

    def resolved(self, min_diameter: float, rod_weight: float) -> ImcLaw:
        delta = self.delta if self.delta is not None else IMC_DELTA_DIAMETERS * min_diameter
        k = self.stiffness if self.stiffness is not None else IMC_STIFFNESS_WEIGHTS * rod_weight / delta
        return replace(self, delta=float(delta), stiffness=float(k))

    def reach(self) -> float:
        # the penalty acts up to delta from touching: pairs and walls must be found there
        return float(self.delta)

    def device_params(self) -> tuple:
        """(k_c, K1, K2, delta, nu), the layout of kernels/imc.py."""
        return (self.stiffness, IMC_SHARPNESS / self.delta, IMC_SHARPNESS / self.nu, self.delta, self.nu)

    def describe(self) -> str:
        d = f"{self.delta:.3g} m" if self.delta is not None else f"{IMC_DELTA_DIAMETERS:g} d"
        k = f"{self.stiffness:.3g} N/m" if self.stiffness is not None else f"{IMC_STIFFNESS_WEIGHTS:g} m g / delta"
        return f"IMC (delta {d}, nu {self.nu:.3g} m/s, k_c {k})"

    def to_dict(self) -> dict:
        return {"name": self.name, "delta_m": self.delta, "nu_m_per_s": self.nu, "stiffness_N_per_m": self.stiffness}


def imc_force(gap, delta: float, stiffness: float):
    """The IMC normal force F(g) (N) at surface gap ``gap`` (m), on the host (NumPy): the same
    law as :func:`rodwarp.kernels.imc.imc_normal_force`, for checks and tests."""
    g = np.asarray(gap, dtype=float)
    k1 = IMC_SHARPNESS / delta
    x = -k1 * g
    sp = np.logaddexp(0.0, x)
    s = 0.5 * (1.0 + np.tanh(0.5 * x))
    return np.where(g > delta, 0.0, 2.0 * stiffness * sp * s / k1)


def imc_creep_speed(load_ratio, nu: float):
    """The slip speed (m/s) at which IMC's smoothed friction balances a tangential load of
    ``load_ratio`` = T / (mu F_n) < 1: (2 / K2) artanh(T / (mu F_n)), K2 = 15 / nu."""
    return 2.0 * nu / IMC_SHARPNESS * np.arctanh(np.asarray(load_ratio, dtype=float))
