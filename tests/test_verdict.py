"""The stability verdict on synthetic metric series, and heights measured from the floor."""

import json

import numpy as np
import pytest

from rodwarp import experiments as vd
from rodwarp.errors import RodwarpError

T0, T = 5.0, 5.0
TIMES = T0 + np.arange(1, 51) * 0.1  # samples every 0.1 s of a 5 s test


def test_pile_that_spreads_flat_while_in_contact_is_unstable():
    # the measured alpha-25 collapse (g = 10, a/g = 1): the centroid sinks to 0.15 of its height,
    # here while one cluster holds every rod (f ~ 0.92) so that only the height can tell
    h = 0.15 + 0.85 * np.exp(-(TIMES - T0) / 0.6)
    f = np.full_like(TIMES, 0.92)
    v = vd.judge(TIMES, T0, h, f)
    assert not v.stable
    assert v.largest_cluster_fraction >= 0.5  # the old rule (f only) would have called it stable
    assert v.height_kept == pytest.approx(0.15, abs=2e-3)
    assert v.persistence < 0.3


def test_pile_that_keeps_its_height_is_stable():
    rng = np.random.default_rng(0)
    h = 0.9 + 0.01 * rng.standard_normal(TIMES.size)
    f = 0.97 + 0.01 * rng.standard_normal(TIMES.size)
    v = vd.judge(TIMES, T0, h, f)
    assert v.stable and v.persistence == 1.0


def test_pile_that_holds_then_collapses_midway_has_persistence_one_half():
    h = np.where(TIMES <= T0 + T / 2, 0.95, 0.2)
    f = np.where(TIMES <= T0 + T / 2, 0.95, 0.3)
    v = vd.judge(TIMES, T0, h, f)
    assert v.persistence == pytest.approx(0.5, abs=0.021)  # one sample of 0.1 s in 5 s
    assert not v.stable


def test_pile_that_breaks_into_loose_rods_at_full_height_is_unstable():
    # height kept but no majority cluster: rods standing apart are not a pile
    v = vd.judge(TIMES, T0, np.full(TIMES.size, 0.95), np.full(TIMES.size, 0.2))
    assert not v.stable and v.persistence == 0.0


def test_a_late_collapse_fails_even_with_high_persistence():
    h = np.where(TIMES < T0 + 4.8, 0.95, 0.15)
    v = vd.judge(TIMES, T0, h, np.full(TIMES.size, 0.9))
    assert v.persistence > 0.9 and not v.stable


def test_persistence_weights_samples_by_the_time_they_cover():
    t = np.array([1.0, 4.0, 5.0])  # uneven: the first sample covers [0, 1], the second [1, 4]
    assert vd.persistence(t, 0.0, [False, True, False]) == pytest.approx(0.6)


def test_thresholds_are_checked_and_reported():
    with pytest.raises(RodwarpError, match="must lie in"):
        vd.Thresholds(height_kept=1.5)
    d = vd.judge(TIMES, T0, np.ones(TIMES.size), np.ones(TIMES.size)).to_dict()
    assert set(d["thresholds"]) == {"height_kept", "cluster", "persistence"}
    assert "persistence >=" in d["rule"]


def test_nan_samples_are_refused():
    h = np.ones(TIMES.size)
    h[3] = np.nan
    with pytest.raises(RodwarpError, match="NaN"):
        vd.judge(TIMES, T0, h, np.ones(TIMES.size))


def _three_rods(z0):
    """Rods of 1 m along x: two stacked at the origin, one far away; floor at z = z0."""
    d = 0.02
    x = np.concatenate([
        np.stack([np.linspace(-0.5, 0.5, 5), np.zeros(5), np.full(5, z0 + d / 2)], 1),
        np.stack([np.zeros(5), np.linspace(-0.5, 0.5, 5), np.full(5, z0 + 1.5 * d)], 1),
        np.stack([np.linspace(3.5, 4.5, 5), np.zeros(5), np.full(5, z0 + d / 2)], 1)])
    return x, np.repeat(np.arange(3), 5), np.ones(15), d


@pytest.mark.parametrize("z0", [0.0, -3.0, 2.5])
def test_heights_are_measured_from_the_floor_plane_not_from_z_zero(z0):
    x, vr, m, d = _three_rods(z0)
    assert vd.centroid_height_above(x, m, z0) == pytest.approx(d * (0.5 + 1.5 + 0.5) / 3)
    # the reference pile is the first two rods; the third lies 4 m away on the floor alone
    ref = vd.pile_reference(0.0, x[:10], vr[:10], m[:10], 2, z0, 1.0, d)
    assert ref.height == pytest.approx(d)
    assert ref.radius == pytest.approx(0.5)  # both rod centroids on the axis, plus half a rod
    in_big = np.array([True, True, False])
    assert vd.rods_left(x, vr, m, 3, z0, in_big, ref) == pytest.approx(1 / 3)


def test_a_low_rod_outside_the_cluster_has_left_the_pile():
    x, vr, m, d = _three_rods(0.0)
    ref = vd.PileReference(0.0, d, (0.0, 0.0), 10.0, 2 * d)  # nobody is far
    assert vd.rods_left(x, vr, m, 3, 0.0, np.array([True, True, False]), ref) == pytest.approx(1 / 3)
    assert vd.rods_left(x, vr, m, 3, 0.0, np.array([True, True, True]), ref) == 0.0


def test_a_centroid_below_the_floor_is_refused():
    x, vr, m, d = _three_rods(0.0)
    with pytest.raises(RodwarpError, match="not above the floor"):
        vd.pile_reference(0.0, x, vr, m, 3, 1.0, 1.0, d)


def test_floor_height_follows_the_wall_and_the_drive():
    from rodwarp.rodset import RodSet
    from rodwarp.sim import Model, ModelBuilder

    rods = RodSet.from_straight([[0, 0, 3.0]], [[1, 0, 0]], 1.0, 0.01)
    assert Model(rods, rod_contacts=False).control().floor_height(0.0) is None
    builder = ModelBuilder(rods, rod_contacts=False)
    builder.add_box([-1, -1, 2.5], [1, 1, 4.0], walls=("floor",), moving=True)
    control = builder.finalize().control()
    control.set_drive(0.001, 10.0)
    assert control.floor_height(0.0) == pytest.approx(2.5)
    assert control.floor_height(0.025) == pytest.approx(2.501)  # a quarter period: the crest
    control.remove_walls(["floor"])
    assert control.floor_height(0.0) is None


def test_raised_floor_run_reports_heights_above_its_floor(tmp_path):
    """--initial rods in a container whose floor is at z = 2: h is measured from z = 2."""
    from rodwarp.experiments import ProtocolParams, run_protocol
    from rodwarp.rodset import RodSet

    rng = np.random.default_rng(1)
    n = 12
    centers = np.column_stack([rng.uniform(0.3, 0.7, n), rng.uniform(0.3, 0.7, n), 2.0 + 0.01 + 0.025 * np.arange(n)])
    ang = rng.uniform(0, np.pi, n)
    rods = RodSet.from_straight(centers, np.column_stack([np.cos(ang), np.sin(ang), np.zeros(n)]), 0.5, 0.01,
                                n_vertices=4)
    rods.box = np.array([[0.0, 0.0, 2.0], [1.0, 1.0, 3.0]])
    src = tmp_path / "raised.npz"
    rods.save(src)
    p = ProtocolParams(alpha=50, length=0.5, initial=str(src), duration=0.2, save_every=0.05, gravity=10.0,
                       freq=16.0, device="cpu")
    s = run_protocol(p, tmp_path / "run", progress=False)
    assert s["test_start"]["height"] == pytest.approx(float(np.mean(centers[:, 2])) - 2.0, rel=0.05)
    assert 0.0 < s["height_kept"] <= 1.05
    again = vd.judge_metrics_csv(tmp_path / "run" / "metrics.csv", t0=s["test_start"]["time"])
    assert again.to_dict() == {k: s[k] for k in ("stable", "height_kept", "persistence", "largest_cluster_fraction",
                                                 "rods_left", "thresholds")} | {"rule": s["stable_rule"]}
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["stable"] == s["stable"]
