"""Rods that roll and spin: friction at the surface against analytic answers (solid cylinders).

A rod lying *across* a slope rolls; one lying *along* it sticks below tan(theta) = mu. Each
case runs with both rod models (ten elastic vertices with twist, and the two-vertex rigid
rod), which must agree with the same closed forms.
"""

import math

import numpy as np
import pytest

from rodwarp.rodset import RodSet
from rodwarp.sim import STEEL, Model, ModelBuilder, RodSolver, run
from rodwarp.testing.scenes import straight_rod, tilted_gravity

G = 9.81
R = 0.01
MODELS = ("elastic", "rigid")


def rod_on_floor(direction, theta_deg, mu, rod_model, center=(0.0, 0.0, R)):
    rods = RodSet.from_polylines([straight_rod(center, direction, 1.0, R)], R)
    builder = ModelBuilder(rods, STEEL, gravity=tilted_gravity(G, theta_deg), mu=mu, rod_contacts=False, rod_model=rod_model)
    builder.add_plane((0, 0, 1), 0.0, mu=mu, name="floor")
    model = builder.finalize()
    return model


def follow(model, duration, dt=1e-3, state=None, iterations=10, velocity=False):
    """Times, mean x of the vertices (or their mean x velocity) and the spin of the first edge,
    every step."""
    solver = RodSolver(model, iterations=iterations)
    ts, xs, ws = [], [], []
    k = "v" if velocity else "x"
    run(solver, state or model.state(), duration, dt,
        callback=lambda s, i: (ts.append(s.time), xs.append(getattr(s, k).numpy()[:, 0].mean()),
                               ws.append(s.spin.numpy()[0])))
    return np.array(ts), np.array(xs), np.array(ws)


@pytest.mark.parametrize("rod_model", MODELS)
@pytest.mark.parametrize("theta", [15.0, 30.0])
def test_rod_across_an_incline_rolls_without_slipping(theta, rod_model):
    th = math.radians(theta)
    assert math.tan(th) <= 3 * 0.4  # rolling without slip is possible
    t, x, w = follow(rod_on_floor((0, 1, 0), theta, 0.4, rod_model), 0.5)
    a = 2 * np.polyfit(t, x, 2)[0]
    exact = 2.0 / 3.0 * G * math.sin(th)
    assert abs(a - exact) / exact < 0.02
    # rolls: the surface point in contact is at rest, omega r = v
    t, v, w = follow(rod_on_floor((0, 1, 0), theta, 0.4, rod_model), 0.2, velocity=True)
    assert np.allclose(w[10:] * R, v[10:], rtol=1e-3)


@pytest.mark.parametrize("rod_model", MODELS)
def test_rod_across_a_steep_incline_slides_and_spins_up(rod_model):
    th, mu = math.radians(60.0), 0.2
    assert math.tan(th) > 3 * mu
    t, x, w = follow(rod_on_floor((0, 1, 0), 60.0, mu, rod_model), 0.5)
    a = 2 * np.polyfit(t, x, 2)[0]
    exact = G * (math.sin(th) - mu * math.cos(th))
    assert abs(a - exact) / exact < 0.02
    alpha = np.polyfit(t, w, 1)[0]
    exact_alpha = 2 * mu * G * math.cos(th) / R
    assert abs(alpha - exact_alpha) / exact_alpha < 0.02


@pytest.mark.parametrize("rod_model", MODELS)
def test_rod_along_an_incline_sticks_below_the_friction_angle(rod_model):
    assert math.tan(math.radians(20.0)) < 0.4
    t, x, w = follow(rod_on_floor((1, 0, 0), 20.0, 0.4, rod_model), 1.0)
    assert np.max(np.abs(x - x[0])) < 1e-6
    assert np.max(np.abs(w)) < 1e-9  # no rolling either


@pytest.mark.parametrize("rod_model", MODELS)
def test_rod_along_an_incline_slides_above_the_friction_angle(rod_model):
    th = math.radians(30.0)
    t, x, w = follow(rod_on_floor((1, 0, 0), 30.0, 0.4, rod_model), 1.0)
    a = 2 * np.polyfit(t, x, 2)[0]
    exact = G * (math.sin(th) - 0.4 * math.cos(th))
    assert abs(exact - 1.507) < 1e-3
    assert abs(a - exact) / exact < 0.02


@pytest.mark.parametrize("rod_model", MODELS)
def test_spinning_rod_set_on_a_floor_ends_rolling_at_one_third(rod_model):
    """Friction spins it down and speeds it up until v = omega r: v = omega0 r / 3."""
    model = rod_on_floor((0, 1, 0), 0.0, 0.3, rod_model)
    state = model.state()
    omega0 = 50.0
    state.set_spin([omega0])
    t, v, w = follow(model, 0.6, state=state, velocity=True)
    exact = omega0 * R / 3
    assert abs(v[-1] - exact) / exact < 0.02
    assert abs(w[-1] * R - v[-1]) / exact < 0.02  # rolling at the end
    # slipping phase: friction decelerates the spin at 2 mu g / r (I = m r^2 / 2)
    slip_time = omega0 * R / (3 * 0.3 * G)
    early = t < 0.5 * slip_time
    alpha = np.polyfit(t[early], w[early], 1)[0]
    assert abs(alpha + 2 * 0.3 * G / R) / (2 * 0.3 * G / R) < 0.02


def test_rod_pushed_through_its_axis_rolls_at_two_thirds_of_F_over_m():
    """A force through the axis, F <= 3 mu m g: rolls without slip with a = 2 F / (3 m)."""
    mu = 0.3
    model = rod_on_floor((0, 1, 0), 0.0, mu, "rigid")
    m = float(model.rod_masses()[0])
    F = 1.5 * mu * m * G  # below 3 mu m g
    # a horizontal push through the axis is a tilt of the body force: g_x = F / m
    model.gravity = np.array([F / m, 0.0, -G])
    t, x, w = follow(model, 0.3)
    a = 2 * np.polyfit(t, x, 2)[0]
    assert abs(a - 2 * F / (3 * m)) / (2 * F / (3 * m)) < 0.02


def test_static_twist_of_a_clamped_rod_under_an_end_torque():
    """Twist angle T x / (G J) along a rod clamped at x = 0 (edge midpoints at x)."""
    from rodwarp.testing.scenes import cantilever

    rods, pinned = cantilever(9, radius=R)
    model = Model(rods, STEEL, gravity=(0, 0, 0), pinned=pinned, rod_contacts=False, damping=0.0)
    T = 5.0
    torque = np.zeros(model.n_vertices)
    last_edge = model.n_vertices - 2
    torque[last_edge] = T
    control = model.control()
    control.set_torque(torque)
    # torsion is stiff and fast: damp it with the spin damping of the model
    model.damping = 2000.0
    solver = RodSolver(model, iterations=20)
    state = run(solver, model.state(), 0.05, 1e-4, control=control)
    theta = state.theta.numpy()
    J = math.pi * R**4 / 2
    GJ = STEEL.shear * J
    x_mid = 0.5 * (rods.points[last_edge, 0] + rods.points[last_edge + 1, 0])
    # the clamp's ghost edge sits just behind x = 0; its midpoint is the reference
    x_ref = 0.5 * (rods.points[0, 0] + rods.points[1, 0])
    exact = T * (x_mid - x_ref) / GJ
    got = theta[last_edge] - theta[0]
    assert abs(got - exact) / exact < 0.02


def tipping_acceleration(rod_model, r, phi_deg=60.0, L=1.0):
    """Angular acceleration of a rod released from rest at phi with its lower end on a floor
    with mu = 1 (it cannot slip there), from its end-to-end angle over 0.03 s."""
    phi = math.radians(phi_deg)
    bottom = np.array([0.0, 0.0, r])
    top = bottom + L * np.array([math.cos(phi), 0.0, math.sin(phi)])
    rods = RodSet.from_polylines([np.linspace(bottom, top, 10)], r)
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -G), mu=1.0, rod_contacts=False, rod_model=rod_model)
    builder.add_plane((0, 0, 1), 0.0, mu=1.0, name="floor")
    model = builder.finalize()
    solver = RodSolver(model, iterations=40, tolerance=0)
    angles, ts = [], []

    def cb(s, i):
        x = s.x.numpy()
        d = x[-1] - x[0]
        angles.append(math.atan2(d[2], d[0]))
        ts.append(s.time)

    run(solver, model.state(), 0.03, 2e-4, callback=cb)
    return -2 * np.polyfit(np.array(ts), np.array(angles) - phi, 2)[0]


def test_rod_tipping_about_its_end_on_a_rough_floor():
    """3 g cos(phi) / (2 l) about the end (inertia m l^2 / 3) for a thin rod. The rigid capsule
    turns about the bottom of its end cap, an offset of r: exactly
    g (l/2) cos(phi) / (l^2/12 + r^2/4 + (l/2)^2 + r^2 + l r sin(phi)), 2.5% below at
    r = l/100 and 1.3% below at r = l/200; the elastic rod turns about its end vertex."""
    phi, L = math.radians(60.0), 1.0
    thin = 3 * G * math.cos(phi) / (2 * L)

    def capsule(r):
        return G * 0.5 * L * math.cos(phi) / (L**2 / 12 + r**2 / 4 + 0.25 * L**2 + r**2 + L * r * math.sin(phi))

    elastic = tipping_acceleration("elastic", 0.01)
    assert abs(elastic - thin) / thin < 0.02
    for r in (0.01, 0.005):
        rigid = tipping_acceleration("rigid", r)
        assert abs(rigid - capsule(r)) / capsule(r) < 0.005
    assert abs(rigid - thin) / thin < 0.02  # r = l / 200
