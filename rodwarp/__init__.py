"""rodwarp: simulate and analyse large packings of elastic rods with NVIDIA Warp.

Host-side API (SI units throughout)::

    from rodwarp import RodSet, Model, RodSolver
"""

from rodwarp.errors import RodwarpError, SimulationBlowUp
from rodwarp.rodset import Contacts, RodSet, load

__version__ = "0.1.0"

__all__ = ["RodSet", "Contacts", "load", "Model", "State", "Material", "STEEL", "RodSolver", "StepInfo",
           "RodwarpError", "SimulationBlowUp", "__version__"]


def __getattr__(name):
    # Warp-backed classes load lazily so `rodwarp --help` and pure I/O stay fast.
    if name in ("Model", "State", "Material", "STEEL", "Plane"):
        from rodwarp import model

        return getattr(model, name)
    if name in ("RodSolver", "StepInfo"):
        from rodwarp import solver

        return getattr(solver, name)
    raise AttributeError(name)
