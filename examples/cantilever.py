"""A clamped rod sagging under its own weight, against Euler-Bernoulli beam theory.

A horizontal rod (L = 1 m, r = 1 cm, E = 1 GPa, rho = 1000 kg/m^3: E I = 7.85 N m^2) of 9
edges is clamped at x = 0 and settles for 1.5 s under gravity with viscous damping (40 1/s).
Its tip sag is compared with the Euler-Bernoulli value q L^4 / (8 E I), q = rho A g the weight
per unit length. The test suite asserts the same within 2% (tests/test_mechanics.py).

    python examples/cantilever.py
"""

import math

import numpy as np

from rodwarp import RodSet
from rodwarp.sim import Material, Model, RodSolver, run

L, r, E, rho, g = 1.0, 0.01, 1e9, 1000.0, 9.81
n_edges = 9                                   # 10 vertices along the beam, as in the protocol's rods
h = L / n_edges

# Vertices along +x; the clamp pins the root (x = 0) and a ghost vertex just behind it
# (x = -1e-3 h), which fixes the tangent.
x = np.concatenate([[-1e-3 * h], np.arange(n_edges + 1) * h])
points = np.stack([x, 0 * x, 0 * x], axis=1)
rods = RodSet.from_polylines([points], r)

model = Model(rods, Material(young=E, density=rho), gravity=(0, 0, -g),
              damping=40.0, pinned=[0, 1], rod_contacts=False)
solver = RodSolver(model, iterations=4)
state = run(solver, model.state(), duration=1.5, dt=1e-3)   # 1500 steps of 1 ms

sag = -state.positions()[-1, 2]               # tip deflection (m)
A, I = math.pi * r**2, math.pi * r**4 / 4
exact = rho * A * g * L**4 / (8 * E * I)
err = (sag - exact) / exact
print(f"tip sag {sag * 1e3:.4f} mm, analytic q L^4/(8 E I) {exact * 1e3:.4f} mm, "
      f"relative error {err:+.4f}")
