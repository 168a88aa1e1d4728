"""The Verlet pair list and its partial refresh: every pair within reach is always listed."""

import numpy as np
import pytest

from rodwarp.experiments._packing import random_packing
from rodwarp.rodset._geometry import segment_distance
from rodwarp.sim import STEEL, ModelBuilder, RodSolver, State


def shaken_pile(seed=0, n_rods=60):
    """Elastic rods (alpha 40, 10 vertices) dropped into a box shaken at 20 g: a few rods
    move fast while the rest settle, which is what the partial refresh is for."""
    d = 0.01
    rods = random_packing(n_rods, 0.4, d, (0.4, 0.4, 0.6), seed=seed)
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -9.81), mu=0.2, rod_model="elastic")
    builder.add_box((0, 0, 0), (0.4, 0.4, 0.8), walls=("floor", "ceiling", "x-", "x+", "y-", "y+"), moving=True)
    model = builder.finalize()
    control = model.control()
    control.set_drive(0.01, 20.0)
    return model, control


def run(model, control, n, *, full_every_step: bool, record=None):
    solver = RodSolver(model, iterations=10)
    a, b = model.state(), State(model)
    vmax, prev = 0.0, None
    for _ in range(n):
        if full_every_step:
            solver.invalidate_pairs()
        dt = solver.adaptive_dt(control, vmax, prev)
        info, dt, _ = solver.adaptive_step(a, b, control, None, dt)
        if record is not None:
            record(solver, a, info, dt)
        a, b = b, a
        vmax, prev = info.max_speed, dt
    return solver, a


def brute_force_gaps(model, x):
    """Capsule gap of every segment pair (m), all pairs at once (host geometry, numpy)."""
    seg = model.arrays.seg_vertex.numpy()
    rad = model.radius_np[model.arrays.vertex_rod.numpy()[seg]]
    p0, p1 = x[seg][:, None, :], x[seg + 1][:, None, :]
    q0, q1 = x[seg][None, :, :], x[seg + 1][None, :, :]
    return segment_distance(p0, p1, q0, q1) - rad[:, None] - rad[None, :]


def test_partial_refresh_gives_the_same_trajectory_as_a_full_rebuild_every_step():
    model, control = shaken_pile()
    fast, a = run(model, control, 150, full_every_step=False)
    ref, b = run(model, control, 150, full_every_step=True)
    assert fast.collision.refreshes > 20  # the partial refresh did the work
    assert fast.pair_builds < 0.3 * ref.pair_builds
    np.testing.assert_array_equal(a.x.numpy(), b.x.numpy())
    np.testing.assert_array_equal(a.v.numpy(), b.v.numpy())


def test_the_refreshed_list_holds_every_pair_within_its_guaranteed_reach():
    """After every refresh the list holds all pairs whose capsule gap is below M - 3 tau
    (the reach it promises; docs/performance.md, "The pair list: refreshed where rods moved"),
    checked against brute force."""
    model, control = shaken_pile(seed=1, n_rods=30)
    seg = model.arrays.seg_vertex.numpy()
    vr = model.arrays.vertex_rod.numpy()
    arc = model.arrays.arc.numpy()
    checked = []

    def record(solver, state_in, info, dt):
        c = solver.collision
        x = state_in.x.numpy()
        # the invariant the reach rests on: no segment has moved by more than tau since its
        # pairs were last found, measured from the pile's mean position
        ref = c._ref.numpy().reshape(-1, 2, 3)
        o = c.sums.numpy()[0] / len(x)
        np.testing.assert_allclose(o, x.mean(axis=0), rtol=0, atol=1e-12)
        moved = np.maximum(np.linalg.norm(x[seg] - o - ref[:, 0], axis=1),
                           np.linalg.norm(x[seg + 1] - o - ref[:, 1], axis=1))
        assert moved.max() <= c.tau * (1 + 1e-9)
        if info.step % 10 or c.refreshes == 0:
            return
        gaps = brute_force_gaps(model, x)
        reach = c.pairs_margin - 3.0 * c.tau
        i, j = np.nonzero(np.triu(gaps < reach - 1e-6, 1))
        # the same-rod exclusion of the broadphase: segments of one rod closer than a diameter
        # of arc length never form a contact
        same = vr[seg[i]] == vr[seg[j]]
        lo, hi = np.minimum(seg[i], seg[j]), np.maximum(seg[i], seg[j])
        keep = ~same | (arc[hi] - arc[lo + 1] >= 2 * model.radius_np[vr[seg[i]]])
        need = set(zip(i[keep].tolist(), j[keep].tolist()))
        listed = {tuple(p) for p in c.pairs.numpy()[:c.pairs_n].tolist()}
        assert len(listed) == c.pairs_n  # no pair twice
        assert need <= listed, f"{len(need - listed)} pairs within reach missing at step {info.step}"
        checked.append(len(need))

    run(model, control, 120, full_every_step=False, record=record)
    assert len(checked) >= 5 and max(checked) > 0


@pytest.mark.parametrize("fraction", [0.0, 1.0])
def test_refresh_limits_fall_back_to_a_full_rebuild(monkeypatch, fraction):
    """With no refresh allowed (limit 0) every flagged step rebuilds the whole list; with a
    limit of 1 no step after the first rebuilds it unless the reach outgrows it."""
    from rodwarp.sim.contacts import ContactPipeline

    monkeypatch.setattr(ContactPipeline, "PARTIAL_LIMIT", fraction)
    model, control = shaken_pile(seed=2, n_rods=30)
    solver, _ = run(model, control, 60, full_every_step=False)
    if fraction == 0.0:
        assert solver.collision.refreshes == 0 and solver.pair_builds > 5
    else:
        assert solver.collision.refreshes > 0
