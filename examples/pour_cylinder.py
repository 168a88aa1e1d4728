"""Rods poured into a cylinder, then the cylinder lifted away: does the packing stand?

Forty rigid steel rods (l = 10 cm, d = 5 mm, aspect ratio 20) are released at random positions
and directions inside a vertical tube of radius 6 cm standing on a floor, fall and settle for
1 s; then the tube is lifted away (taken out of the scene) and the packing is left for 1 s more.
Printed: the pile's height and radius in the tube (every rod inside it) and after the lift. At
this low aspect ratio the packing spreads; the paper's alpha 200 packings stand.

    python examples/pour_cylinder.py
"""

import numpy as np

from rodwarp import STEEL, RodSet
from rodwarp.sim import ModelBuilder, RodSolver, run
from rodwarp.sim.walls import Cylinder

n, length, r, R_tube = 40, 0.10, 0.0025, 0.06                  # m
rng = np.random.default_rng(0)
rods = []
for k in range(n):                                              # one rod per 1.2 cm of height: no overlaps
    phi = rng.uniform(0, np.pi)
    d = np.array([np.cos(phi), np.sin(phi), rng.uniform(-0.05, 0.05)])  # nearly lying: they fit the tube
    d /= np.linalg.norm(d)
    c = np.array([*rng.uniform(-0.5, 0.5, 2) * (R_tube - 0.5 * length), 0.02 + 0.012 * k])
    rods.append(c + np.outer(np.linspace(-0.5, 0.5, 2) * length, d))
builder = ModelBuilder(RodSet.from_polylines(rods, r), STEEL, gravity=(0, 0, -9.81), mu=0.3, rod_model="rigid")
builder.add_plane((0, 0, 1), 0.0, name="floor")
builder.add_wall(Cylinder.make((0, 0, 0), (0, 0, 1), R_tube, name="tube"))
model = builder.finalize()
solver = RodSolver(model)
control = model.control()
dt = solver.default_dt(control)


def shape(state):
    x = state.positions()
    return x[:, 2].max() + r, np.hypot(x[:, 0], x[:, 1]).max() + r   # height, radius (m)


points = solver.contacts()   # the contact points, carried from one run to the next (warm start)
state = run(solver, model.state(), 1.0, dt, control=control, contacts=points)
h0, r0 = shape(state)
inside = model.walls[1].distance(state.positions()).min() >= r - 0.02 * 2 * r
print(f"in the tube: height {h0 * 100:.2f} cm, radius {r0 * 100:.2f} cm (tube {R_tube * 100:.0f} cm), "
      f"every rod inside: {inside}")
control.remove_walls(["tube"])                                  # the tube lifted away
state = run(solver, state, 1.0, dt, control=control, contacts=points)
h1, r1 = shape(state)
print(f"after the lift: height {h1 * 100:.2f} cm, radius {r1 * 100:.2f} cm")
