"""Walls of every kind against known answers: a rod sliding down the inside of a tilted
cylinder, rods poured into a cylinder staying inside it, a piston (a floor moved by a prescribed
ramp) carrying a column whose weight its force balances at rest."""

import math

import numpy as np
import pytest

from rodwarp.errors import RodwarpError
from rodwarp.rodset import RodSet
from rodwarp.sim import STEEL, Model, ModelBuilder, RodSolver, run
from rodwarp.sim.walls import Cylinder, Plane
from rodwarp.testing.scenes import log_cabin, straight_rod, tilted_gravity

G = 9.81
R = 0.01
RC = 0.1  # cylinder radius (m)


def rod_in_tilted_cylinder(theta_deg, mu):
    """A rod along the axis (x) of a horizontal cylinder, lying on its lowest line; gravity
    tilted by theta toward +x: the cylinder inclined by theta."""
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, -(RC - R)), (1, 0, 0), 1.0, R)], R)
    builder = ModelBuilder(rods, STEEL, gravity=tilted_gravity(G, theta_deg), mu=mu, rod_contacts=False)
    builder.add_wall(Cylinder.make((0, 0, 0), (1, 0, 0), RC, name="tube"))
    model = builder.finalize()
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
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -G), mu=0.3)
    builder.add_plane((0, 0, 1), 0.0, name="floor")
    builder.add_wall(Cylinder.make((0, 0, 0), (0, 0, 1), RC, name="tube"))
    model = builder.finalize()
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
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -G), mu=0.5)
    floor = builder.add_plane((0, 0, 1), 0.0, moving=True, name="floor")  # the piston
    model = builder.finalize()
    control = model.control()
    control.set_ramp(0.02, 0.25)  # up by 5 mm in 0.25 s, then held
    solver = RodSolver(model, iterations=100)
    dt = 1e-3
    points = solver.contacts()
    state = run(solver, model.state(), 1.0, dt, control=control, contacts=points)
    assert control.floor_height(1.0) == pytest.approx(0.005)
    x = state.x.numpy()
    assert x[:, 2].min() - R == pytest.approx(0.005, abs=0.01 * 2 * R)  # the column rode up with it
    P = len(model.walls)
    k = [w.name for w in model.walls].index(floor.name)
    force = points.wall_impulse.numpy().reshape(-1, P, 3)[:, k] / dt  # per vertex (N)
    weight = STEEL.density * math.pi * R**2 * 1.0 * G * rods.n_rods  # eight 1 m rods
    assert force[:, 2].sum() == pytest.approx(weight, rel=1e-3)
    assert np.abs(force[:, :2].sum(axis=0)).max() < 1e-6 * weight


def test_walls_are_named_once_and_cylinders_need_a_radius():
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, 0.5), (1, 0, 0), 1.0, R)], R)
    builder = ModelBuilder(rods, STEEL)
    builder.add_wall(Cylinder.make((0, 0, 0), (0, 0, 2), 1.0))
    model = builder.finalize()
    assert isinstance(model.walls[0], Cylinder) and np.allclose(model.walls[0].axis, (0, 0, 1))
    assert model.walls[0].mu == model.mu  # the model's friction unless given
    with pytest.raises(RodwarpError, match="already has a wall named 'cylinder'"):
        builder.add_wall(Cylinder.make((0, 0, 0), (0, 0, 1), 1.0))
    with pytest.raises(RodwarpError, match="already has a wall named 'floor'"):
        Model(rods, STEEL, walls=[Plane.make((0, 0, 1), 0.0, name="floor"), Plane.make((0, 0, 1), 1.0, name="floor")])
    with pytest.raises(RodwarpError, match="radius must be a positive length"):
        Cylinder.make((0, 0, 0), (0, 0, 1), 0.0, name="c2")
    assert model.planes == []


def test_a_finalized_model_does_not_change():
    """The builder's finalize() gives a model of its walls then; later changes to the builder
    make other models, never this one, and a model has no way to add a wall."""
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, 0.5), (1, 0, 0), 1.0, R)], R)
    builder = ModelBuilder(rods, STEEL, mu=0.4)
    builder.add_plane((0, 0, 1), 0.0, name="floor")
    model = builder.finalize()
    builder.add_wall(Cylinder.make((0, 0, 0), (0, 0, 1), 1.0, name="tube"))
    builder.walls[0].offset = 5.0
    assert [w.name for w in model.walls] == ["floor"] and model.walls[0].offset == 0.0
    assert model.walls[0].mu == 0.4 and builder.walls[0].mu is None  # the builder's walls are not filled in
    assert [w.name for w in builder.finalize().walls] == ["floor", "tube"]
    assert not hasattr(model, "add_wall") and isinstance(model.walls, tuple)
    assert np.allclose(builder.box if builder.box is not None else [0], [0])
    builder.add_box((-1, -1, 0), (1, 1, 1), walls=("x-",))
    assert np.allclose(builder.finalize().box, [[-1, -1, 0], [1, 1, 1]]) and model.box is None
