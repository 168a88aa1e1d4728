"""Rod mechanics against analytic answers (docs/physics.md)."""

import math

import numpy as np
import pytest

from rodwarp.sim.model import Material, Model
from rodwarp.rodset import RodSet
from rodwarp.testing.scenes import (
    TEST_DENSITY, TEST_RADIUS, TEST_YOUNG, cantilever, cantilever_frequency, cantilever_sag, straightened,
)
from rodwarp.sim.solver import RodSolver, run

TEST_MAT = Material(young=TEST_YOUNG, density=TEST_DENSITY)




def settle_cantilever(n_edges, dt=1e-3, duration=1.5, damping=40.0, **solver_kw):
    rods, pinned = cantilever(n_edges)
    model = Model(rods, TEST_MAT, gravity=(0, 0, -9.81), damping=damping, pinned=pinned, rod_contacts=False)
    solver = RodSolver(model, iterations=4, **solver_kw)
    state = run(solver, model.state(), duration, dt)
    return -state.positions()[-1, 2]


def test_cantilever_sag_default_discretisation():
    sag = settle_cantilever(9)
    exact = cantilever_sag()
    assert abs(sag - exact) / exact < 0.02


def test_cantilever_sag_converges_under_refinement():
    exact = cantilever_sag()
    errs = [abs(settle_cantilever(n) - exact) / exact for n in (4, 8, 16)]
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 0.01


def tip_frequency(n_edges=9, dt=2e-4, duration=1.2):
    rods, pinned = cantilever(n_edges)
    model = Model(rods, TEST_MAT, gravity=(0, 0, 0), pinned=pinned, rod_contacts=False)
    # initial condition: small tip velocity excites mostly the first mode
    v = np.zeros_like(rods.points)
    xs = rods.points[:, 0].clip(0, None)
    v[:, 2] = 0.01 * (xs / xs.max()) ** 2
    model.rods = rods.with_points(rods.points, velocities=v)
    solver = RodSolver(model, iterations=2)
    zs, ts = [], []
    run(solver, model.state(), duration, dt, callback=lambda s, i: (zs.append(s.x.numpy()[-1, 2]), ts.append(s.time)))
    z = np.array(zs)
    t = np.array(ts)
    z = z - z.mean()
    up = np.flatnonzero((z[:-1] < 0) & (z[1:] >= 0))
    tc = t[up] - z[up] * (t[up + 1] - t[up]) / (z[up + 1] - z[up])
    return 1.0 / np.mean(np.diff(tc))


def test_cantilever_first_frequency():
    f = tip_frequency()
    exact = cantilever_frequency()
    assert abs(exact - 2.80) < 0.01
    assert abs(f - exact) / exact < 0.03


def test_axial_static_stretch_matches_FL_over_EA():
    # a rod hanging from its top vertex: the top edge carries (almost) the full weight
    n = 10
    L = 1.0
    pts = np.stack([np.zeros(n), np.zeros(n), -np.linspace(0, L, n)], axis=1)
    rods = RodSet.from_polylines([pts], TEST_RADIUS)
    soft = Material(young=1e6, density=TEST_DENSITY)
    model = Model(rods, soft, gravity=(0, 0, -9.81), damping=30.0, pinned=[0], rod_contacts=False, extensible=True)
    solver = RodSolver(model, iterations=30)
    state = run(solver, model.state(), 2.0, 1e-3)
    z = state.positions()[:, 2]
    # total elongation of a bar under its own weight: rho g L^2 / (2 E) (continuum);
    # the lumped model puts half an edge of mass at the bottom vertex, exact for the top edges.
    A = math.pi * TEST_RADIUS**2
    h = L / (n - 1)
    masses = np.full(n, TEST_DENSITY * A * h)
    masses[[0, -1]] *= 0.5
    below = np.cumsum(masses[::-1])[::-1][1:]  # weight carried by each edge
    expected = np.sum(below * 9.81 * h / (soft.young * A))
    stretch = (-z[-1]) - L
    assert abs(stretch - expected) / expected < 0.02


def test_free_rod_momentum_and_no_energy_drift():
    # a bent, spinning rod in free space, explicit (symplectic) bending below its bound
    n = 10
    s = np.linspace(0, 1, n)
    pts = np.stack([s, 0.05 * np.sin(np.pi * s), np.zeros(n)], axis=1)
    rods = RodSet.from_polylines([pts], TEST_RADIUS, rest_points=straightened(pts))
    v = np.zeros_like(pts)
    v[:, 1] = 0.3 * (s - 0.5)
    v[:, 2] = 0.1
    model = Model(rods.with_points(pts, velocities=v), TEST_MAT, gravity=(0, 0, 0), rod_contacts=False)
    # the rest curvature is zero, so the initially bent rod vibrates while it spins and drifts
    solver = RodSolver(model, iterations=3, bending="explicit")
    dt = 0.5 * solver.explicit_bending_dt()
    energies = []
    p0 = (model.mass_np[:, None] * v).sum(axis=0)

    def cb(st, info):
        energies.append(solver.energy(st)["total"])

    state = run(solver, model.state(), 10000 * dt, dt, callback=cb)
    e = np.array(energies)
    first = e[:1000].mean()
    last = e[-1000:].mean()
    assert abs(last - first) / first < 2e-3
    p1 = (model.mass_np[:, None] * state.velocities()).sum(axis=0)
    assert np.linalg.norm(p1 - p0) <= 1e-9 * np.linalg.norm(p0)


def helix(n=30, turns=1.0, radius=0.1, pitch=0.05):
    t = np.linspace(0, 2 * np.pi * turns, n)
    return np.stack([radius * np.cos(t), radius * np.sin(t), pitch * t / (2 * np.pi)], axis=1)


def pair_distances(x):
    return np.linalg.norm(x[:, None] - x[None], axis=-1)


def test_curved_rod_at_rest_shape_stays_put_under_rigid_motion():
    # a helix at its rest shape, rotated and moved: no elastic force, no motion
    pts = helix()
    th = 0.7
    R = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    moved = pts @ R.T + np.array([0.3, -0.2, 0.5])
    rods = RodSet.from_polylines([moved], 0.005, rest_points=pts)
    model = Model(rods, TEST_MAT, gravity=(0, 0, 0), rod_contacts=False)
    assert model.curved
    solver = RodSolver(model)
    state = model.state()
    assert solver.energy(state)["bending"] < 1e-20
    state = run(solver, state, 0.2, solver.default_dt())
    assert np.max(np.abs(state.positions() - moved)) < 1e-9


def test_curved_rod_recovers_its_natural_shape():
    # a helix flattened and straightened towards a line springs back to its rest shape
    # (up to a rigid motion) under damping: natural curvature and torsion are kept
    pts = helix()
    flat = pts.copy()
    flat[:, 2] = 0.0
    flat = 0.5 * flat + 0.5 * straightened(pts) * 0.5
    rods = RodSet.from_polylines([flat], 0.005, rest_points=pts)
    model = Model(rods, TEST_MAT, gravity=(0, 0, 0), damping=20.0, rod_contacts=False, extensible=False)
    solver = RodSolver(model)
    state = run(solver, model.state(), 3.0, 1e-3)
    d_rest = pair_distances(pts)
    err0 = np.abs(pair_distances(flat) - d_rest).max()
    err = np.abs(pair_distances(state.positions()) - d_rest).max()
    assert err < 0.02 * err0


def test_twisting_the_clamp_of_a_curved_rod_turns_its_shape_with_it():
    """Twist-bend coupling: an arc clamped at one end whose clamp is turned by psi about its
    tangent settles into its rest shape turned by psi (a straight rod's shape would not change)."""
    Rc, n = 2.0, 10
    s = np.linspace(0.0, 1.0, n)
    arc = np.stack([Rc * np.sin(s / Rc), Rc * (1 - np.cos(s / Rc)), np.zeros(n)], axis=1)
    h = 1.0 / (n - 1)
    pts = np.vstack([[-1e-3 * h, 0.0, 0.0], arc])  # ghost vertex: the clamp fixes the tangent
    rods = RodSet.from_polylines([pts], 0.005)
    model = Model(rods, TEST_MAT, gravity=(0, 0, 0), damping=30.0, pinned=[0, 1], rod_contacts=False)
    assert model.curved
    state = model.state()
    psi = math.radians(30.0)
    theta = np.zeros(model.n_vertices)
    theta[0] = psi  # the clamped edge's material frame, turned
    import warp as wp

    state.theta.assign(wp.array(theta, dtype=wp.float64))
    solver = RodSolver(model, iterations=20)
    state = run(solver, state, 3.0, 1e-3)
    c, sn = math.cos(psi), math.sin(psi)
    Rx = np.array([[1, 0, 0], [0, c, -sn], [0, sn, c]])
    expected = pts @ Rx.T
    x = state.positions()
    moved = np.linalg.norm(expected[-1] - pts[-1])
    assert moved > 0.1
    assert np.max(np.linalg.norm(x - expected, axis=1)) < 0.02 * moved
