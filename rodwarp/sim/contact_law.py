"""Which law acts at the rods' contacts: one tagged kind, a host module and a device module per law.

A contact law acts on rod-rod and rod-wall contacts alike. Each law is

* a host module, ``rodwarp/sim/law_<name>.py``: a frozen dataclass subclass of
  :class:`ContactLaw` holding the law's parameters (their checks, defaults and units) and
  packing them for the device (:meth:`ContactLaw.device_params`);
* a device module, ``kernels/<name>.py``: the law's ``wp.func`` s with the interface of
  :mod:`rodwarp.kernels.contact_laws`;
* its registration: one line in the table of this module (:func:`register_contact_law`, which
  gives the law its device tag); a law of your own is registered by calling it.

Built in: ``exact`` (:class:`~rodwarp.sim.law_exact.ExactLaw`, the default: Signorini
non-penetration and the Coulomb cone, sticking exactly; docs/physics.md, "Contact") and
``imc`` (:class:`~rodwarp.sim.law_imc.ImcLaw`, DisMech's incremental potential contact;
docs/physics.md, "The IMC contact law").

>>> ContactLaw.from_tag("imc", nu=1e-3)          # or ImcLaw(nu=1e-3), or ContactLaw("imc", nu=1e-3)
ImcLaw(delta=None, nu=0.001, stiffness=None)
"""

from __future__ import annotations

from rodwarp.sim._law import CONTACT_LAWS, ContactLaw, register_contact_law
from rodwarp.sim.law_exact import ExactLaw
from rodwarp.sim.law_imc import ImcLaw

# the registry: one line per built-in law, in device-tag order
for _law in (ExactLaw, ImcLaw):
    register_contact_law(_law)

#: the built-in laws' names (callers that list them; CONTACT_LAWS holds any registered later too)
LAWS = tuple(CONTACT_LAWS)

# IMC's constants and host formulas, where callers first found them (their home: law_imc)
from rodwarp.sim.law_imc import (IMC_DELTA_DIAMETERS, IMC_MAX_STIFFNESS, IMC_NU, IMC_SHARPNESS,  # noqa: E402
                                 IMC_STIFFNESS_WEIGHTS, imc_creep_speed, imc_force)

__all__ = ["CONTACT_LAWS", "ContactLaw", "ExactLaw", "ImcLaw", "LAWS", "register_contact_law", "IMC_DELTA_DIAMETERS",
           "IMC_MAX_STIFFNESS", "IMC_NU", "IMC_SHARPNESS", "IMC_STIFFNESS_WEIGHTS", "imc_creep_speed", "imc_force"]
