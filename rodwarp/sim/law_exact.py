"""The exact contact law (host side): Signorini non-penetration and the Coulomb cone, sticking exactly.

No parameters: the friction coefficients are the model's and the walls'. Device functions:
:mod:`rodwarp.kernels.exact`; docs/physics.md, "Contact".
"""

from __future__ import annotations

from dataclasses import dataclass

from rodwarp.kernels import exact
from rodwarp.sim._law import ContactLaw


@dataclass(frozen=True)
class ExactLaw(ContactLaw):
    """Signorini and the Coulomb cone (the default law): no penetration, true sticking; the
    solver's post-stabilisation removes what overlap the step leaves."""

    name = "exact"
    device = exact

    def describe(self) -> str:
        return "exact (Signorini and the Coulomb cone)"

    def to_dict(self) -> dict:
        from rodwarp.sim.law_imc import IMC_NU

        # IMC's keys too, with IMC's defaults: the summaries keep one layout for every law
        return {"name": self.name, "delta_m": None, "nu_m_per_s": IMC_NU, "stiffness_N_per_m": None}
