"""Contact and Coulomb friction against analytic answers; failure detection."""

import math
import warnings

import numpy as np
import pytest

from rodwarp.errors import RodwarpError, SimulationBlowUp
from rodwarp.rodset import RodSet
from rodwarp.sim.builder import ModelBuilder
from rodwarp.sim.model import STEEL, Material, Model  # noqa: F401
from rodwarp.sim.solver import RodSolver, run
from rodwarp.testing.scenes import log_cabin, straight_rod, straightened, tilted_gravity

G = 9.81




def rod_on_rails(theta_deg, mu=0.3, duration=0.5, downhill=(0, 1, 0)):
    """Rod C along y resting across two fixed rails along x; gravity tilted along ``downhill``:
    along C's own axis (y) it can only slide over the rails, along the rails (x) it rolls."""
    r = 0.01
    rails = [straight_rod((0, -0.3, 0), (1, 0, 0), 1.0, r), straight_rod((0, 0.3, 0), (1, 0, 0), 1.0, r)]
    top = straight_rod((0, 0, 2 * r), (0, 1, 0), 1.0, r)
    rods = RodSet.from_polylines(rails + [top], r)
    model = Model(rods, STEEL, gravity=tilted_gravity(G, theta_deg, downhill=downhill), mu=mu, pinned=np.arange(20))
    solver = RodSolver(model, iterations=20)
    dt = 1e-3
    k = int(np.argmax(np.abs(downhill)))
    ts, xs = [], []
    run(solver, model.state(), duration, dt, callback=lambda s, i: (ts.append(s.time), xs.append(s.x.numpy()[20:, k].mean())))
    return np.array(ts), np.array(xs)


@pytest.mark.parametrize("theta", [10.0, 15.0])
def test_rod_sliding_along_its_axis_over_tilted_rails_sticks_below_mu(theta):
    assert math.tan(math.radians(theta)) < 0.3
    t, x = rod_on_rails(theta)
    assert np.max(np.abs(x - x[0])) < 1e-6


@pytest.mark.parametrize("theta", [20.0, 30.0])
def test_rod_sliding_along_its_axis_over_tilted_rails_slides_above_mu(theta):
    t, x = rod_on_rails(theta)
    th = math.radians(theta)
    exact = G * (math.sin(th) - 0.3 * math.cos(th))
    a = 2 * np.polyfit(t, x, 2)[0]
    assert abs(a - exact) / exact < 0.03


@pytest.mark.parametrize("theta", [10.0, 30.0])
def test_rod_across_rails_tilted_along_them_rolls(theta):
    """Gravity along the rails, across the rod: it rolls on them, a = (2/3) g sin(theta)
    (tan(theta) <= 3 mu), whether or not tan(theta) exceeds mu."""
    th = math.radians(theta)
    t, x = rod_on_rails(theta, downhill=(1, 0, 0), duration=0.3)
    a = 2 * np.polyfit(t, x, 2)[0]
    exact = 2.0 / 3.0 * G * math.sin(th)
    assert abs(a - exact) / exact < 0.02


def cabin_drift(mu, duration=2.0):
    rods = log_cabin(layers=4, rods_per_layer=2)
    builder = ModelBuilder(rods, STEEL, gravity=tilted_gravity(G, 5.0, downhill=(1, 1, 0)), mu=mu)
    builder.add_plane((0, 0, 1), 0.0, mu=mu, name="floor")
    model = builder.finalize()
    solver = RodSolver(model)
    x0 = rods.points.copy()
    state = run(solver, model.state(), duration, solver.default_dt())
    return np.max(np.linalg.norm(state.positions() - x0, axis=1))


def test_log_cabin_on_a_tilted_floor_rolls_apart_even_with_friction():
    # round logs on a 5 degree tilt roll (each layer rolls on the one below like a rod on
    # rails): friction alone does not hold a log cabin of cylinders; real ones are notched
    assert cabin_drift(0.2, duration=1.0) > 0.05


def test_log_cabin_collapses_without_friction():
    assert cabin_drift(0.0, duration=1.0) > 0.1


def ladder_slip(phi, mu, rod_model, duration=1.0, iterations=40, n_vertices=10):
    """Largest slip (m) of the rod's ends along the floor and the wall over ``duration``."""
    from rodwarp.testing.scenes import leaning_rod

    builder = ModelBuilder(leaning_rod(phi, n_vertices=n_vertices), STEEL, gravity=(0, 0, -G), mu=mu, rod_contacts=False, rod_model=rod_model)
    builder.add_plane((0, 0, 1), 0.0, name="floor")
    builder.add_plane((1, 0, 0), 0.0, name="wall")
    model = builder.finalize()
    solver = RodSolver(model, iterations=iterations)
    x0 = model.rods.points.copy()
    state = run(solver, model.state(), duration, solver.default_dt())
    x = state.positions()
    return max(abs(x[0, 0] - x0[0, 0]), abs(x[-1, 2] - x0[-1, 2]))


def test_ladder_stands_without_creep_when_friction_suffices():
    from rodwarp.testing.scenes import ladder_min_angle

    assert ladder_min_angle(0.5, 0.5) == pytest.approx(36.87, abs=0.01)
    assert ladder_slip(60.0, 0.5, "rigid") < 1e-6
    # the elastic rod holds too once Gauss-Seidel has converged
    assert ladder_slip(60.0, 0.5, "elastic", iterations=200) < 1e-6


@pytest.mark.xfail(strict=True, reason="engine gap: at the default 40 sweeps Gauss-Seidel has not converged on the "
                                       "elastic ladder (residual 1e-3 m/s) and its foot creeps about 0.3 mm/s")
def test_elastic_ladder_stands_at_the_default_effort():
    assert ladder_slip(60.0, 0.5, "elastic") < 1e-6


def test_fewer_vertices_creep_less_under_the_same_sweeps():
    # the gap above depends on the resolution: an axial load on an inextensible elastic rod
    # reaches a vertex-local contact solve only through many sweeps, so a ten-vertex ladder
    # creeps at the protocol's 10 sweeps and even at 40; three vertices (the resolution rule's
    # choice for the laboratory's rods) hold it 20-100x better (docs/physics.md)
    c3, c10 = ladder_slip(60.0, 0.5, "elastic", n_vertices=3), ladder_slip(60.0, 0.5, "elastic")
    assert c3 < 1e-5 < 1e-4 < c10
    assert ladder_slip(60.0, 0.5, "elastic", iterations=10) > 10 * ladder_slip(60.0, 0.5, "elastic", iterations=10,
                                                                              n_vertices=3)


@pytest.mark.parametrize("rod_model", ["elastic", "rigid"])
def test_ladder_slides_down_when_friction_is_too_small(rod_model):
    from rodwarp.testing.scenes import ladder_min_angle

    assert ladder_min_angle(0.2, 0.2) > 60.0
    assert ladder_slip(60.0, 0.2, rod_model, duration=0.3) > 0.05


def test_frictionless_collision_conserves_momentum():
    r = 0.01
    a = straight_rod((0, 0, 0), (0, 1, 0), 1.0, r)
    b = straight_rod((0.3, 0.1, 0.005), (0, 0, 1), 1.0, r)
    rods = RodSet.from_polylines([a, b], r)
    v = np.zeros_like(rods.points)
    v[:10, 0] = 2.0
    v[10:, 1] = -0.3
    model = Model(rods.with_points(rods.points, velocities=v), STEEL, gravity=(0, 0, 0), mu=0.0)
    solver = RodSolver(model, iterations=20)
    p0 = (model.mass_np[:, None] * v).sum(axis=0)
    hits = []
    state = run(solver, model.state(), 0.3, 1e-4, callback=lambda s, i: hits.append(i.n_contacts))
    assert max(hits) > 0  # they did collide
    p1 = (model.mass_np[:, None] * state.velocities()).sum(axis=0)
    assert np.linalg.norm(p1 - p0) <= 1e-9 * np.linalg.norm(p0)
    # and the collision changed rod A's momentum
    pa = (model.mass_np[:10, None] * state.velocities()[:10]).sum(axis=0)
    assert pa[0] < 0.99 * (model.mass_np[:10].sum() * 2.0)


@pytest.mark.parametrize("factor", [1.0, 10.0])
def test_no_tunnelling_of_thin_fast_rod(factor):
    # at the default step and at 10x it (where one step moves the rod several radii),
    # speculative contacts catch the approach
    d = 1.0 / 300
    r = d / 2
    fixed = straight_rod((0, 0, 0), (1, 0, 0), 1.0, r)
    falling = straight_rod((0, 0, 0.05), (0, 1, 0), 1.0, r)
    rods = RodSet.from_polylines([fixed, falling], r)
    v = np.zeros_like(rods.points)
    v[10:, 2] = -5.0
    model = Model(rods.with_points(rods.points, velocities=v), STEEL, gravity=(0, 0, -G), mu=0.2,
                  pinned=np.arange(10))
    solver = RodSolver(model, allow_unstable=True)
    dt = factor * solver.default_dt()
    from rodwarp.rodset import segment_distance

    gaps, sides = [], []

    def watch(s, i):
        x = s.x.numpy()
        a, b = x[:10], x[10:]
        gaps.append(segment_distance(a[:-1, None], a[1:, None], b[None, :-1], b[None, 1:]).min() - d)
        # height of the falling rod's centreline where it crosses the fixed one (y = 0)
        k = np.searchsorted(b[:, 1], 0.0)
        w = (0.0 - b[k - 1, 1]) / (b[k, 1] - b[k - 1, 1])
        sides.append((1 - w) * b[k - 1, 2] + w * b[k, 2])

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run(solver, model.state(), 0.1, dt, callback=watch)
    if factor > 1:
        assert 5.0 * dt > 2 * d  # one step at impact speed moves the rod more than its diameter
    assert min(gaps) > -0.1 * d  # never overlaps by more than 10% of d
    assert min(sides) > 0.9 * d  # still above the fixed rod where they cross
    assert min(gaps) < 0.1 * d  # and it did reach it


def test_step_above_bound_is_refused_or_flagged():
    r = 0.01
    rods = RodSet.from_polylines([straight_rod((0, 0, r), (1, 0, 0), 1.0, r)], r)
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -G))
    builder.add_plane((0, 0, 1), 0.0)
    model = builder.finalize()
    solver = RodSolver(model)
    bound = solver.max_stable_dt()
    with pytest.raises(RodwarpError, match="stability bound"):
        solver.check_dt(2 * bound)
    loose = RodSolver(model, allow_unstable=True)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        loose.check_dt(2 * bound)
    assert any("stability bound" in str(x.message) for x in w)


def test_unstable_explicit_bending_stops_with_clear_message():
    r = 0.02
    n = 10
    s = np.linspace(0, 1, n)
    pts = np.stack([s, 0.02 * np.sin(3 * np.pi * s), np.zeros(n)], axis=1)
    model = Model(RodSet.from_polylines([pts], r, rest_points=straightened(pts)), STEEL, gravity=(0, 0, 0),
                  rod_contacts=False)
    solver = RodSolver(model, bending="explicit", allow_unstable=True, iterations=2)
    dt = 3.0 * solver.explicit_bending_dt()
    state = model.state()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(SimulationBlowUp) as err:
            run(solver, state, 2000 * dt, dt)
    msg = str(err.value)
    assert "step" in msg and "explicit bending" in msg
    assert np.all(np.isfinite(state.positions()))  # nothing non-finite escaped


def test_implicit_bending_is_stable_where_explicit_fails():
    r = 0.02
    n = 10
    s = np.linspace(0, 1, n)
    pts = np.stack([s, 0.02 * np.sin(3 * np.pi * s), np.zeros(n)], axis=1)
    model = Model(RodSet.from_polylines([pts], r, rest_points=straightened(pts)), STEEL, gravity=(0, 0, 0),
                  rod_contacts=False)
    solver = RodSolver(model, bending="implicit", iterations=2)
    dt = 10.0 * solver.explicit_bending_dt()
    state = model.state()
    e0 = solver.energy(state)["total"]
    state = run(solver, state, 500 * dt, dt)
    assert np.all(np.isfinite(state.positions()))
    assert solver.energy(state)["total"] <= e0  # implicit Euler only removes energy


def test_a_finely_divided_rod_does_not_collide_with_itself_along_its_axis():
    """Edges of 0.85 d: segments two apart overlap in the rest shape. They are not a contact
    (they could touch only if the rod bent to a radius below its own); a free straight rod
    stays exactly at rest instead of pushing itself apart."""
    r = 0.01
    rods = RodSet.from_polylines([straight_rod((0, 0, 0), (1, 0, 0), 0.5, r, n_vertices=31)], r)
    assert np.diff(rods.points[:, 0]).max() < 0.9 * 2 * r
    model = Model(rods, STEEL, gravity=(0, 0, 0))
    solver = RodSolver(model)
    state = model.state()
    infos = []
    run(solver, state, 0.05, 1e-3, callback=lambda s, i: infos.append(i))
    assert max(i.n_contacts for i in infos) == 0
    assert np.abs(state.positions() - rods.points).max() < 1e-12


def test_a_folded_rod_still_collides_with_itself():
    """A hairpin whose legs (0.5 d apart, an arc of 2.4 d between them) are thrown at each
    other at 1 m/s relative speed: self-contact stops them, they never pass through. A soft
    rod whose rest shape is straight: it unfolds far slower than the legs meet."""
    r = 0.01
    leg = np.linspace(0.3, 0.0, 16)
    turn = np.linspace(-np.pi / 2, np.pi / 2, 9)[1:-1]
    R = 0.015
    pts = np.concatenate([
        np.stack([leg, np.zeros_like(leg), np.zeros_like(leg)], 1),
        np.stack([-R * np.cos(turn), R + R * np.sin(turn), np.zeros_like(turn)], 1),
        np.stack([leg[::-1], np.full_like(leg, 2 * R), np.zeros_like(leg)], 1)])
    v = np.zeros_like(pts)
    v[:16, 1] = 0.5
    v[-16:, 1] = -0.5
    rods = RodSet.from_polylines([pts], r)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    straight = np.stack([arc, np.zeros_like(arc), np.zeros_like(arc)], 1)
    rods = RodSet(rods.points, rods.offsets, rods.radii, velocities=v, rest_points=straight)
    soft = Material(young=1e5, density=1000.0, poisson=0.45)
    model = Model(rods, soft, gravity=(0, 0, 0))
    solver = RodSolver(model)
    state = model.state()
    gaps = []

    def record(s, info):
        p = s.positions()
        gaps.append(np.min(p[-16:-8, 1]) - np.max(p[:8, 1]) - 2 * r)  # the legs' straight tips

    run(solver, state, 0.03, 2e-4, callback=record)
    assert min(gaps) > -0.05 * 2 * r  # without self-contact the tips would cross by 0.02 m
    assert gaps[-1] > min(gaps)  # and they come apart again
