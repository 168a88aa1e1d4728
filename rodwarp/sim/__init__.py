"""The simulation engine, in the Model / State / Control / solver shape of Warp's examples and Newton.

>>> from rodwarp.sim import ModelBuilder, RodSolver
>>> builder = ModelBuilder(rods, gravity=(0, 0, -9.81), rod_model="rigid")   # doctest: +SKIP
>>> builder.add_box([0, 0, 0], [1, 1, 2.5])                                   # doctest: +SKIP
>>> model = builder.finalize()                                # fixed from here
>>> control = model.control()                                 # walls in place, drive, torques
>>> solver = RodSolver(model)
>>> state_0, state_1, contacts = model.state(), model.state(), solver.contact_points()
>>> dt = solver.default_dt(control)
>>> for _ in range(1000):
...     solver.collide(state_0, control, dt, contacts)
...     solver.step(state_0, state_1, control, contacts, dt)
...     state_0, state_1 = state_1, state_0

(``run(solver, state, duration, dt, control=control)`` does that loop.)

A step runs in phases (:meth:`RodSolver.step`): predict (frames, velocity predictor), the
step's parameters, rod-rod contact points prepared and warm-started, wall contacts found and
prepared, rods factored, Gauss-Seidel solve, advance (positions, overlap projection, frames),
checks.

What is called a contact, and its name here:

* *contact candidates*: segment pairs close enough to meet, the broadphase's Verlet list
  (``ContactPipeline.pairs``, :mod:`rodwarp.sim.contacts`);
* *contact points*: where a step's solver acts between rods, speculative ones included
  (:class:`ContactPoints`, from :meth:`RodSolver.contact_points`; ``StepInfo.n_contacts``;
  the device's ``RodContacts`` view);
* *wall contacts*: a rod vertex within reach of a wall in a step (the device's ``WallContacts``);
* *contacts of the packing*: touching rod pairs, one per pair (:func:`packing_contacts`,
  a :class:`rodwarp.rodset.Contacts`);
* the model's ``rod_contacts`` switch: whether rod-rod contact points are detected at all;
* the *contact law* acting at contact points and wall contacts (:class:`ContactLaw`, one
  host and one device module per law, :data:`CONTACT_LAWS`).

Host code lives here (one file per concern: ``builder``, ``model``, ``state``, ``control``, ``contacts``,
``walls``, ``contact_law`` with one ``law_<name>`` module per law, ``solver`` with its step bounds
in ``_bounds``, and ``metrics``: the contacts of the packing and the centroid height of a state);
device code lives in :mod:`rodwarp.kernels`, grouped by stage.
The model, its units and its step bounds are described in docs/physics.md.
"""

from rodwarp.sim._bounds import STEPS_PER_PERIOD
from rodwarp.sim.builder import ModelBuilder
from rodwarp.sim.contact_law import CONTACT_LAWS, ContactLaw, register_contact_law
from rodwarp.sim.contacts import ContactPoints
from rodwarp.sim.control import Control, Drive
from rodwarp.sim.law_exact import ExactLaw
from rodwarp.sim.law_imc import ImcLaw
from rodwarp.sim.metrics import centroid_height, packing_contacts, rod_contacts
from rodwarp.sim.model import ROD_MODELS, STEEL, Material, Model
from rodwarp.sim.solver import RodSolver, StepInfo, run
from rodwarp.sim.state import State
from rodwarp.sim.walls import Plane

__all__ = ["CONTACT_LAWS", "ContactLaw", "ContactPoints", "Control", "Drive", "ExactLaw", "ImcLaw", "Material", "Model",
           "ModelBuilder", "Plane", "ROD_MODELS", "RodSolver", "STEEL", "STEPS_PER_PERIOD", "State", "StepInfo",
           "centroid_height", "packing_contacts", "register_contact_law", "rod_contacts", "run"]
