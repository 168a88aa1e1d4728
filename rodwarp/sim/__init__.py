"""The simulation engine, in the Model / State / Control / solver shape of Warp's examples and Newton.

>>> from rodwarp.sim import ModelBuilder, RodSolver
>>> builder = ModelBuilder(rods, gravity=(0, 0, -9.81), rod_model="rigid")   # doctest: +SKIP
>>> builder.add_box([0, 0, 0], [1, 1, 2.5])                                   # doctest: +SKIP
>>> model = builder.finalize()                                # fixed from here
>>> control = model.control()                                 # walls in place, drive, torques
>>> solver = RodSolver(model)
>>> state_0, state_1, contacts = model.state(), model.state(), solver.contacts()
>>> dt = solver.default_dt(control)
>>> for _ in range(1000):
...     solver.collide(state_0, control, dt, contacts)
...     solver.step(state_0, state_1, control, contacts, dt)
...     state_0, state_1 = state_1, state_0

(``run(solver, state, duration, dt, control=control)`` does that loop.)

Host code lives here (one file per concern: ``builder``, ``model``, ``state``, ``control``, ``contacts``,
``solver`` with its step bounds in ``_bounds``, and ``metrics``: the contacts of the packing and
the centroid height of a state); device code lives in :mod:`rodwarp.kernels`, grouped by stage.
The model, its units and its step bounds are described in docs/physics.md.
"""

from rodwarp.sim._bounds import STEPS_PER_PERIOD
from rodwarp.sim.builder import ModelBuilder
from rodwarp.sim.contact_law import ContactLaw
from rodwarp.sim.contacts import ContactPoints
from rodwarp.sim.control import Control, Drive
from rodwarp.sim.metrics import centroid_height, rod_contacts
from rodwarp.sim.model import ROD_MODELS, STEEL, Material, Model
from rodwarp.sim.solver import RodSolver, StepInfo, run
from rodwarp.sim.state import State
from rodwarp.sim.walls import Plane

__all__ = ["ContactLaw", "ContactPoints", "Control", "Drive", "Material", "Model", "ModelBuilder", "Plane",
           "ROD_MODELS", "RodSolver", "STEEL", "STEPS_PER_PERIOD", "State", "StepInfo", "centroid_height", "rod_contacts", "run"]
