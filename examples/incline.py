"""A rod lying across an incline rolls down it without slipping, at a = (2/3) g sin(theta).

A steel rod (l = 1 m, r = 1 cm, 10 vertices) lies across a floor inclined by theta = 30
degrees, friction coefficient mu = 0.4 (rolling without slip needs tan(theta) <= 3 mu). The
incline is modelled by tilting gravity over a flat floor. The rod's downhill acceleration,
fitted to its position over 0.5 s, is compared with (2/3) g sin(theta), the acceleration of
a solid cylinder rolling without slip; its surface speed omega r is compared with its speed
v. Both rod models run: elastic (10 vertices) and rigid (a two-vertex capsule).

    python examples/incline.py
"""

import math

import numpy as np

from rodwarp import STEEL, RodSet
from rodwarp.sim import ModelBuilder, RodSolver, run

g, r, mu, theta = 9.81, 0.01, 0.4, math.radians(30.0)
gravity = (g * math.sin(theta), 0.0, -g * math.cos(theta))   # downhill is +x
exact = 2 / 3 * g * math.sin(theta)                           # m/s^2

s = np.linspace(-0.5, 0.5, 10)
rod = np.stack([0 * s, s, r + 0 * s], axis=1)                # along y: across the slope, on z = 0
for rod_model in ("elastic", "rigid"):
    builder = ModelBuilder(RodSet.from_polylines([rod], r), STEEL, gravity=gravity, mu=mu,
                           rod_contacts=False, rod_model=rod_model)
    builder.add_plane((0, 0, 1), 0.0, mu=mu, name="floor")
    model = builder.finalize()
    t, x, v, w = [], [], [], []

    def record(state, info):
        t.append(state.time)
        x.append(state.positions()[:, 0].mean())           # mean downhill position (m)
        v.append(state.velocities()[:, 0].mean())          # downhill speed (m/s)
        w.append(state.spins()[0])                         # spin about the rod's axis (rad/s)

    run(RodSolver(model, iterations=10), model.state(), duration=0.5, dt=1e-3, callback=record)
    a = 2 * np.polyfit(t, x, 2)[0]                           # x = x0 + v0 t + a t^2 / 2
    print(f"{rod_model}: a = {a:.5f} m/s^2, analytic (2/3) g sin(theta) = {exact:.5f} m/s^2, "
          f"relative error {(a - exact) / exact:+.2e}; at t = {t[-1]:.2f} s omega r = {w[-1] * r:.5f} m/s, "
          f"v = {v[-1]:.5f} m/s")
