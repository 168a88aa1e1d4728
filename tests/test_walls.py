"""Walls of every kind against known answers: a piston (a floor moved by a prescribed ramp)
carrying a column whose weight its force balances at rest."""

import math

import numpy as np
import pytest

from rodwarp.sim import STEEL, Model, RodSolver, run
from rodwarp.testing.scenes import log_cabin

G = 9.81
R = 0.01


def test_piston_carries_a_column_and_its_force_balances_the_weight_at_rest():
    rods = log_cabin(layers=4, rods_per_layer=2, radius=R)
    model = Model(rods, STEEL, gravity=(0, 0, -G), mu=0.5)
    floor = model.add_plane((0, 0, 1), 0.0, moving=True, name="floor")  # the piston
    control = model.control()
    control.set_ramp(0.02, 0.25)  # up by 5 mm in 0.25 s, then held
    solver = RodSolver(model, iterations=100)
    dt = 1e-3
    state = run(solver, model.state(), 1.0, dt, control=control)
    assert control.floor_height(1.0) == pytest.approx(0.005)
    x = state.x.numpy()
    assert x[:, 2].min() - R == pytest.approx(0.005, abs=0.01 * 2 * R)  # the column rode up with it
    P = len(model.walls)
    k = model.walls.index(floor)
    force = state.wall_impulse.numpy().reshape(-1, P, 3)[:, k] / dt  # per vertex (N)
    weight = STEEL.density * math.pi * R**2 * 1.0 * G * rods.n_rods  # eight 1 m rods
    assert force[:, 2].sum() == pytest.approx(weight, rel=1e-3)
    assert np.abs(force[:, :2].sum(axis=0)).max() < 1e-6 * weight
