"""rodwarp: simulate and analyse large packings of elastic rods with NVIDIA Warp.

Host-side API (SI units throughout)::

    from rodwarp import RodSet, ModelBuilder, Model, RodSolver, Control, State, ContactPoints

Subpackages, each with a flat public face: :mod:`rodwarp.rodset` (the rod set, its formats and
contacts, files, run folders), :mod:`rodwarp.sim` (the engine), :mod:`rodwarp.analysis`
(local fields, ACN, statistics, figures), :mod:`rodwarp.ct` (CT volumes, phantoms,
segmentation), :mod:`rodwarp.experiments` (the paper's protocol, the verdict, sweeps, the
phase diagram); :mod:`rodwarp.testing` holds the validation material (an independent NumPy oracle of
the fields, scenes with analytic answers; docs/validation.md).  The README's "Layout" section
draws the layers; docs/physics.md and docs/protocol.md describe the model and the experiment.
"""

from rodwarp.errors import RodwarpError, SimulationBlowUp
from rodwarp.rodset import Contacts, RodSet, load

from rodwarp._version import __version__

__all__ = ["RodSet", "Contacts", "load", "ModelBuilder", "Model", "State", "ContactPoints", "Control", "Material",
           "STEEL", "RodSolver", "StepInfo", "RodwarpError", "SimulationBlowUp", "__version__"]

_SIM = ("ModelBuilder", "Model", "State", "ContactPoints", "Control", "Drive", "Material", "STEEL", "Plane", "RodSolver", "StepInfo", "run")


def __getattr__(name):
    # Warp-backed classes load lazily so `rodwarp --help` and pure I/O stay fast.
    if name in _SIM:
        from rodwarp import sim

        return getattr(sim, name)
    raise AttributeError(name)
