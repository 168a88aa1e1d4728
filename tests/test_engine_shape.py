"""The engine's shape (docs/engine.md): a builder that finalizes a fixed Model, contacts from a
collide step, ``step(state_in, state_out, control, contacts, dt)``.

Known answers: the explicit collide-then-step loop and the solver's own contacts give the same
trajectory bit for bit; a step refused or blown up leaves ``contacts.last`` as it was, so the
retry is bit-identical to a first try at the shorter step; contact points saved with
``to_numpy`` and loaded replay the run bit for bit (the checkpoint keeps the names the arrays had
in the State); and contacts collided for another state, step or control are refused.
"""

import numpy as np
import pytest

from rodwarp.errors import RodwarpError, SimulationBlowUp, StepTooLarge
from rodwarp.experiments import random_packing
from rodwarp.sim import STEEL, ModelBuilder, RodSolver, State

G = 9.81


def pile(seed=2, n_rods=24):
    rods = random_packing(n_rods, 0.3, 0.01, (0.3, 0.3, 0.5), seed=seed)
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -G), mu=0.3, rod_model="rigid")
    builder.add_box((0, 0, 0), (0.3, 0.3, 0.5), walls=("floor", "x-", "x+", "y-", "y+"))
    model = builder.finalize()
    return model, RodSolver(model)


def explicit_loop(model, solver, n, dt, points=None, state=None):
    control = model.control()
    a = model.state() if state is None else state
    b = State(model)
    points = solver.contacts() if points is None else points
    for _ in range(n):
        solver.collide(a, control, dt, points)
        solver.step(a, b, control, points, dt)
        a, b = b, a
    return a, points


def test_collide_then_step_equals_the_solvers_own_contacts_bit_for_bit():
    model, solver = pile()
    dt = solver.default_dt()
    a, points = explicit_loop(model, solver, 120, dt)
    assert points.count > 10  # the pile has settled onto itself and the floor
    model2, solver2 = pile()
    x, y = model2.state(), State(model2)
    for _ in range(120):
        solver2.step(x, y, dt=dt)
        x, y = y, x
    np.testing.assert_array_equal(a.positions(), x.positions())
    np.testing.assert_array_equal(a.velocities(), x.velocities())
    assert points.count == solver2.default_contacts.count


def test_saved_contact_points_replay_the_run_bit_for_bit():
    """A checkpoint's state and contact points (the warm start) continue the run exactly; the
    contact arrays keep the names they had inside the State."""
    model, solver = pile()
    dt = solver.default_dt()
    a, points = explicit_loop(model, solver, 80, dt)
    saved = {k: np.array(v, copy=True) for k, v in {**a.to_numpy(), **points.to_numpy()}.items()}
    assert {"contact_key", "contact_seg", "contact_st", "contact_normal", "contact_gap", "contact_impulse",
            "wall_impulse"} <= set(saved)
    ref, _ = explicit_loop(model, solver, 40, dt, points=points, state=a)
    model2, solver2 = pile()
    s = model2.state()
    s.load_numpy(saved)
    p = solver2.contacts()
    p.load_numpy(saved)
    out, _ = explicit_loop(model2, solver2, 40, dt, points=p, state=s)
    np.testing.assert_array_equal(out.positions(), ref.positions())
    # a cold start (no warm start) from the same state is a different trajectory: the impulses matter
    cold, _ = explicit_loop(model2, RodSolver(model2), 40, dt, state=_copy(model2, saved))
    assert not np.array_equal(cold.velocities(), ref.velocities())


def _copy(model, saved):
    s = model.state()
    s.load_numpy(saved)
    return s


def test_a_refused_step_leaves_the_warm_start_so_the_retry_is_bit_identical():
    model, solver = pile()
    dt = solver.default_dt()
    a, points = explicit_loop(model, solver, 60, dt)
    control = model.control()
    keep_state, keep_points = _copy(model, {k: np.array(v, copy=True) for k, v in a.to_numpy().items()}), solver.contacts()
    keep_points.copy_from(points)
    b = State(model)
    solver.collide(a, control, 50 * dt, points)
    with pytest.raises(StepTooLarge):
        solver.step(a, b, control, points, 50 * dt)
    np.testing.assert_array_equal(points.last.impulse.numpy()[:points.count],
                                  keep_points.last.impulse.numpy()[:keep_points.count])
    solver.collide(a, control, dt, points)
    solver.step(a, b, control, points, dt)
    # the same step from an untouched copy
    other, c = State(model), keep_points
    solver.collide(keep_state, control, dt, c)
    solver.step(keep_state, other, control, c, dt)
    np.testing.assert_array_equal(b.velocities(), other.velocities())


def test_a_blown_up_step_leaves_the_last_contacts():
    model, solver = pile()
    solver.penetration_limit = 1e-9  # any overlap at all is a "blow-up": the first touching step fails
    dt = solver.default_dt()
    control = model.control()
    a, b, points = model.state(), State(model), solver.contacts()
    n_ok = 0
    with pytest.raises(SimulationBlowUp):
        for _ in range(400):
            solver.collide(a, control, dt, points)
            before = points.count, points.last.key.numpy()[:points.count].copy()
            solver.step(a, b, control, points, dt)
            a, b = b, a
            n_ok += 1
    assert n_ok > 0
    assert points.count == before[0] and np.array_equal(points.last.key.numpy()[:points.count], before[1])


def test_contacts_collided_for_another_step_are_refused():
    model, solver = pile()
    dt = solver.default_dt()
    control = model.control()
    a, b, points = model.state(), State(model), solver.contacts()
    with pytest.raises(RodwarpError, match="not collided for this step"):
        solver.step(a, b, control, points, dt)  # never collided
    solver.collide(a, control, dt, points)
    with pytest.raises(RodwarpError, match="not collided for this step"):
        solver.step(a, b, control, points, 0.5 * dt)  # another dt
    with pytest.raises(RodwarpError, match="not collided for this step"):
        solver.step(a, b, model.control(), points, dt)  # another control
    with pytest.raises(RodwarpError, match="pass the step as dt="):
        solver.step(a, b, control, dt)  # the old positional dt
    solver.step(a, b, control, points, dt)
    with pytest.raises(RodwarpError, match="not collided for this step"):
        solver.step(b, a, control, points, dt)  # used once: collide again for the next step
    other_model, other_solver = pile(seed=3)
    with pytest.raises(RodwarpError, match="another model"):
        solver.collide(a, control, dt, other_solver.contacts())
