"""The simulation engine, in the Model / State / Control / solver shape of Warp's examples and Newton.

>>> from rodwarp.sim import Model, RodSolver, run
>>> model = Model(rods, gravity=(0, 0, -9.81), rod_model="rigid")   # doctest: +SKIP
>>> model.add_box([0, 0, 0], [1, 1, 2.5])                             # doctest: +SKIP
>>> control = model.control()                                        # walls, drive, torques
>>> solver = RodSolver(model)
>>> state = run(solver, model.state(), 1.0, solver.default_dt(control), control=control)

Host code lives here (one file per concern: ``model``, ``state``, ``control``, ``contacts``,
``solver`` with its step bounds in ``_bounds``, and ``metrics``: the contacts of the packing and
the centroid height of a state); device code lives in :mod:`rodwarp.kernels`, grouped by stage.
The model, its units and its step bounds are described in docs/physics.md.
"""

from rodwarp.sim.contact_law import ContactLaw
from rodwarp.sim.control import Control, Drive
from rodwarp.sim.metrics import centroid_height, rod_contacts
from rodwarp.sim.model import ROD_MODELS, STEEL, Material, Model
from rodwarp.sim.solver import RodSolver, StepInfo, run
from rodwarp.sim.state import State
from rodwarp.sim.walls import Plane

__all__ = ["ContactLaw", "Control", "Drive", "Material", "Model", "Plane", "ROD_MODELS", "RodSolver", "STEEL", "State",
           "StepInfo", "centroid_height", "rod_contacts", "run"]
