"""Walls of every kind against known answers: a rod sliding down the inside of a tilted
cylinder, rods poured into a cylinder staying inside it, a piston (a floor moved by a prescribed
ramp) carrying a column whose weight its force balances at rest."""

import math

import numpy as np
import pytest

from rodwarp.errors import RodwarpError
from rodwarp.rodset import RodSet
from rodwarp.sim import STEEL, Model, RodSolver, run
from rodwarp.sim.walls import Cylinder
from rodwarp.testing.scenes import log_cabin, straight_rod, tilted_gravity

G = 9.81
R = 0.01
RC = 0.1  # cylinder radius (m)


def rod_in_tilted_cylinder(theta_deg, mu):
    """A rod along the axis (x) of a horizontal cylinder, lying on its lowest line; gravity
    tilted by theta toward +x: the cylinder inclined by theta."""
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, -(RC - R)), (1, 0, 0), 1.0, R)], R)
    model = Model(rods, STEEL, gravity=tilted_gravity(G, theta_deg), mu=mu, rod_contacts=False)
    model.add_wall(Cylinder.make((0, 0, 0), (1, 0, 0), RC, name="tube"))
    return model


def test_rod_slides_down_the_inside_of_an_inclined_cylinder_at_g_sin_minus_mu_cos():
    th, mu = math.radians(30.0), 0.2
    model = rod_in_tilted_cylinder(30.0, mu)
    ts, vs = [], []
    state = run(RodSolver(model), model.state(), 0.3, 1e-3,
                callback=lambda s, i: (ts.append(s.time), vs.append(s.v.numpy()[:, 0].mean())))
    a = np.polyfit(ts[50:], vs[50:], 1)[0]
    assert a == pytest.approx(G * (math.sin(th) - mu * math.cos(th)), rel=1e-3)
    x = state.x.numpy()
    # it slides along the lowest line of the tube, resting on it (within the contact slop)
    assert np.abs(x[:, 1]).max() < 1e-6
    assert np.allclose(x[:, 2], -(RC - R), atol=0.01 * 2 * R)


def test_rod_in_an_inclined_cylinder_sticks_below_the_friction_angle():
    model = rod_in_tilted_cylinder(5.0, 0.2)  # tan 5 deg = 0.087 < 0.2
    state = run(RodSolver(model), model.state(), 0.3, 1e-3)
    assert np.abs(state.v.numpy()[:, 0]).max() < 1e-12  # no slip along the tube (it still settles radially)


def test_rods_poured_into_a_cylinder_stay_inside_it():
    rng = np.random.default_rng(3)
    polys = []
    for k in range(12):  # short rods at random directions inside a vertical tube, stacked in height
        d = rng.normal(size=3)
        d[2] = abs(d[2]) + 0.5
        d /= np.linalg.norm(d)
        polys.append(straight_rod((0.0, 0.0, 0.1 + 0.1 * k), d, 0.12, 0.005, n_vertices=4))
    rods = RodSet.from_polylines(polys, 0.005)
    model = Model(rods, STEEL, gravity=(0, 0, -G), mu=0.3)
    model.add_plane((0, 0, 1), 0.0, name="floor")
    model.add_wall(Cylinder.make((0, 0, 0), (0, 0, 1), RC, name="tube"))
    solver = RodSolver(model)
    control = model.control()
    state = run(solver, model.state(), 0.6, solver.default_dt(control), control=control)
    x = state.x.numpy()
    radial = np.hypot(x[:, 0], x[:, 1])
    assert radial.max() <= RC - 0.005 + 0.02 * 0.01  # inside the tube, within the slop
    assert x[:, 2].min() >= 0.005 - 0.02 * 0.01  # on the floor
    assert x[:, 2].max() < 0.5  # fallen
    # the wall's own distance function says the same
    assert model.walls[1].distance(x).min() >= 0.005 - 0.02 * 0.01


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


def test_walls_are_named_once_and_cylinders_need_a_radius():
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, 0.5), (1, 0, 0), 1.0, R)], R)
    model = Model(rods, STEEL)
    model.add_wall(Cylinder.make((0, 0, 0), (0, 0, 2), 1.0))
    assert isinstance(model.walls[0], Cylinder) and np.allclose(model.walls[0].axis, (0, 0, 1))
    assert model.walls[0].mu == model.mu  # the model's friction unless given
    with pytest.raises(RodwarpError, match="already has a wall named 'cylinder'"):
        model.add_wall(Cylinder.make((0, 0, 0), (0, 0, 1), 1.0))
    with pytest.raises(RodwarpError, match="radius must be a positive length"):
        Cylinder.make((0, 0, 0), (0, 0, 1), 0.0, name="c2")
    assert model.planes == []


def test_a_model_is_final_once_a_state_or_solver_exists():
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, 0.5), (1, 0, 0), 1.0, R)], R)
    model = Model(rods, STEEL)
    model.add_plane((0, 0, 1), 0.0, name="floor")
    model.state()
    with pytest.raises(RodwarpError, match="the model is final"):
        model.add_wall(Cylinder.make((0, 0, 0), (0, 0, 1), 1.0))
    assert [w.name for w in model.walls] == ["floor"]
    other = Model(rods, STEEL)
    RodSolver(other)
    with pytest.raises(RodwarpError, match="the model is final"):
        other.add_box((-1, -1, 0), (1, 1, 1))
