"""The exact contact law (host side): Signorini non-penetration and the Coulomb cone, sticking exactly.

One parameter, the Newton coefficient of restitution ``restitution`` (0, the default: perfectly
inelastic); the friction coefficients are the model's and the walls'. Device functions:
:mod:`rodwarp.kernels.exact` (the restitution acts on the normal target,
:func:`rodwarp.kernels.friction.restitution_target`); docs/physics.md, "Contact" and
"Restitution".
"""

from __future__ import annotations

from dataclasses import dataclass

from rodwarp.arguments import real
from rodwarp.kernels import exact
from rodwarp.sim._law import ContactLaw

#: a contact bounces only when it approaches faster than this many times gravity's speed gain
#: in one step (|g| dt), and faster than BOUNCE_MIN_SPEED: a resting contact's approach under
#: gravity is one |g| dt per step, so it never bounces (no jitter)
BOUNCE_STEPS = 2.0
#: ... and at least this speed (m/s), the threshold without gravity
BOUNCE_MIN_SPEED = 1e-3


def bounce_speed(gravity: float, dt: float) -> float:
    """The approach speed v_min (m/s) a contact must exceed to bounce at step ``dt`` (s) under
    gravity of magnitude ``gravity`` (m/s^2): max(2 |g| dt, 1 mm/s)."""
    return max(BOUNCE_STEPS * abs(gravity) * dt, BOUNCE_MIN_SPEED)


@dataclass(frozen=True)
class ExactLaw(ContactLaw):
    """Signorini and the Coulomb cone (the default law): no penetration, true sticking; the
    solver's post-stabilisation removes what overlap the step leaves.

    Parameters
    ----------
    restitution : float
        Newton coefficient of restitution e in [0, 1]: a contact approaching faster than
        :func:`bounce_speed` at the start of a step, and touching or closing within it, leaves
        at no less than e times its approach speed. 0 (the default): perfectly inelastic, the
        law without the option, bit for bit.
    """

    name = "exact"
    device = exact

    restitution: float = 0.0

    def __post_init__(self):
        real("restitution", self.restitution, ge=0, le=1, hint="the coefficient of restitution e, 0 (perfectly "
             "inelastic) to 1 (elastic)")

    def describe(self) -> str:
        if self.restitution > 0:
            return f"exact (Signorini and the Coulomb cone, restitution e {self.restitution:g})"
        return "exact (Signorini and the Coulomb cone)"

    def to_dict(self) -> dict:
        from rodwarp.sim.law_imc import IMC_NU

        # IMC's keys too, with IMC's defaults: the summaries keep one layout for every law
        d = {"name": self.name, "delta_m": None, "nu_m_per_s": IMC_NU, "stiffness_N_per_m": None}
        if self.restitution > 0:
            d["restitution"] = self.restitution  # only when set: default summaries as before
        return d
