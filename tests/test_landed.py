"""The test's length in drive cycles (--cycles), its sampling per cycle (--samples-per-cycle) and
the landed measures (docs/verdict.md, "The landed phase"), with known answers: a thrown pile whose
centroid is known at every phase, a pile that keeps its landed height while a fixed-phase sample
sees it in flight, and a pile that comes apart in the last cycles."""

import json
import math

import numpy as np
import pytest

from rodwarp.errors import RodwarpError
from rodwarp.experiments import ProtocolParams
from rodwarp.experiments import _verdict as vd

FREQ = 5.0
K = 8  # samples per cycle


def _times(cycles: int, per: int = K, freq: float = FREQ) -> np.ndarray:
    return np.arange(1, cycles * per + 1) / (per * freq)


def _thrown(t, landed: float, apex: float, freq: float = FREQ) -> np.ndarray:
    """A pile thrown every cycle: at ``landed`` for the first half of a cycle, in a parabolic
    flight of height ``apex`` above it in the second."""
    ph = (t * freq) % 1.0
    flight = np.clip(ph - 0.5, 0.0, None) * 2.0  # 0 .. 1 over the second half
    return landed + apex * 4.0 * flight * (1.0 - flight)


def test_landed_height_is_the_lowest_sample_of_each_cycle_not_the_one_in_flight():
    t = _times(50)
    h = _thrown(t, 0.9, 3.0)
    # the last sample of the test falls mid-flight: the end-of-test value is the flight's
    h[-1] = 4.2
    f = np.full_like(t, 0.95)
    m = vd.landed(t, 0.0, FREQ, h, f, per_cycle=K)
    assert m["cycles"] == 50 and m["cycles_averaged"] == 5
    assert m["height_kept"] == pytest.approx(0.9, abs=1e-9)
    assert m["largest_cluster_fraction"] == pytest.approx(0.95)
    assert m["persistence"] == 1.0 and m["stable"] is True
    assert m["per_cycle"]["cycle"] == list(range(1, 51))


def test_a_pile_that_comes_apart_in_the_last_cycles_is_unstable_by_its_landed_measures():
    t = _times(50)
    h = _thrown(t, 0.9, 2.0)
    # from cycle 44 on the pile lands as a layer (h 0.15) and falls apart (f 0.3), although a
    # sample in flight still sees the cluster high up
    late = t * FREQ > 43
    h = np.where(late & ((t * FREQ) % 1.0 <= 0.5), 0.15, h)
    f = np.where(late, 0.3, 0.95)
    m = vd.landed(t, 0.0, FREQ, h, f, per_cycle=K)
    assert m["height_kept"] == pytest.approx(0.15)
    assert m["largest_cluster_fraction"] == pytest.approx(0.3)
    assert m["persistence"] == pytest.approx(43 / 50)
    assert m["stable"] is False


def test_landed_persistence_counts_cycles_and_the_last_five_are_averaged():
    t = _times(20)
    landed_h = np.repeat(np.linspace(1.0, 0.05, 20), K)  # sinking by 0.05 a cycle
    h = landed_h + np.tile(np.r_[0.0, np.full(K - 1, 0.5)], 20)  # the first sample of a cycle is the lowest
    f = np.full_like(t, 0.9)
    m = vd.landed(t, 0.0, FREQ, h, f, per_cycle=K)
    assert m["height_kept"] == pytest.approx(np.mean(np.linspace(1.0, 0.05, 20)[-5:]))
    # cycles with a landed h >= 0.26: 1.0 - 0.05 (k - 1) >= 0.26 for k <= 15
    assert m["persistence"] == pytest.approx(15 / 20)


def test_too_few_samples_per_cycle_leave_the_landed_measures_empty_and_say_why():
    t = _times(50, per=2)
    m = vd.landed(t, 0.0, FREQ, np.ones_like(t), np.ones_like(t), per_cycle=2)
    assert m["height_kept"] is None and m["stable"] is None
    assert "at least 4" in m["why"] and "--samples-per-cycle" in m["why"]
    m = vd.landed(t, 0.0, 0.0, np.ones_like(t), np.ones_like(t), per_cycle=0)
    assert m["stable"] is None and "no drive" in m["why"]


def test_a_partial_last_cycle_is_left_out():
    t = _times(10)[:-3]  # the test ends 5/8 into cycle 10
    h = _thrown(t, 0.8, 1.0)
    m = vd.landed(t, 0.0, FREQ, h, np.full_like(t, 0.9), per_cycle=K)
    assert m["cycles"] == 9


def test_cycles_set_the_test_duration_from_the_frequency():
    p = ProtocolParams(alpha=25, freq=15.92, gravity=10, cycles=50, entangle_duration=0.2).validate().params
    assert p.duration == pytest.approx(50 / 15.92)
    # the sweep's default duration alongside is no conflict; a duration given that disagrees is
    bad = ProtocolParams(alpha=25, freq=15.92, gravity=10, cycles=50, duration=2.0, entangle_duration=0.2)
    with pytest.raises(RodwarpError, match="both set the stability test's length"):
        bad.validate()
    with pytest.raises(RodwarpError, match="--cycles 50 counts drive periods"):
        ProtocolParams(alpha=25, freq=0.0, gravity=10, cycles=50, entangle_duration=0.2).validate()


def test_samples_per_cycle_sample_the_test_and_not_the_entangling():
    from rodwarp.experiments._plan import frames
    from rodwarp.experiments.protocols import plan

    p = ProtocolParams(alpha=25, freq=10.0, gravity=10, cycles=20, samples_per_cycle=8, entangle_duration=1.0,
                       save_every=0.1).validate().params
    ent, test = plan(p)
    assert ent.interval(p.save_every) == pytest.approx(0.1)
    assert test.interval(p.save_every) == pytest.approx(1 / 80)
    # start + (10 + 1) entangling + (160 + 1) test frames
    assert frames((ent, test), p.save_every) == 1 + 11 + 161


def test_a_run_reports_the_landed_measures_and_the_sweep_row_carries_them(tmp_path):
    from rodwarp.experiments._sweep import RESULT_KEYS, _landed_columns, run_point

    point = {"alpha": 15.0, "freq": 40.0, "gravity": 10.0, "static_load": 0.0, "seed": 0, "amplitude": 0.001,
             "entangle_duration": 0.2, "duration": 5.0, "cycles": 12, "samples_per_cycle": 8, "fields_every": 0.0,
             "device": "cpu", "id": "p", "_analyze": {}}
    row = run_point(point, str(tmp_path / "p"))
    assert row["status"] == "ok", row["status"]
    s = json.loads((tmp_path / "p" / "summary.json").read_text())
    assert s["parameters"]["duration"] == pytest.approx(12 / 40)
    landed = s["landed"]
    assert landed["cycles"] == 12 and landed["why"] is None
    assert landed["samples_per_cycle"] == pytest.approx(8)
    # the landed h of a cycle is its lowest sample's h, read back from metrics.csv
    import csv

    rows = [r for r in csv.DictReader(open(tmp_path / "p" / "metrics.csv")) if r["stage"] == "stability"]
    h = np.array([float(r["height_kept"]) for r in rows])
    assert len(rows) == 12 * 8
    per = h.reshape(12, 8).min(axis=1)
    assert landed["per_cycle"]["height_kept"] == pytest.approx(per.tolist())
    assert landed["height_kept"] == pytest.approx(per[-5:].mean())
    assert row["cycles_tested"] == pytest.approx(12) and row["test_duration_s"] == pytest.approx(0.3)
    assert row["height_kept_landed"] == pytest.approx(landed["height_kept"])
    assert row["stable_landed"] == landed["stable"]
    assert {"height_kept_landed", "cluster_landed", "persistence_landed", "stable_landed"} <= set(RESULT_KEYS)
    assert _landed_columns({"parameters": {"duration": 1.0}, "freq": 3.0})["stable_landed"] is None


def test_the_cli_refuses_cycles_with_a_disagreeing_duration(tmp_path):
    from typer.testing import CliRunner

    from rodwarp.cli import app

    r = CliRunner().invoke(app, ["simulate", "--cycles", "10", "--duration", "3", "--freq", "10",
                                 "--out", str(tmp_path / "x")])
    assert r.exit_code == 2
    assert "both set the stability test's length" in r.output
    assert "Traceback" not in r.output
    assert not (tmp_path / "x").exists()


def test_throw_height_and_scaled_entangling_of_the_controls_study():
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import alpha_star_controls as m
    # the paper scale keeps the paper's entangling exactly
    assert m.entangling("paper") == pytest.approx({"entangle_amplitude": 0.05, "entangle_freq": 10.0,
                                                   "entangle_duration": 5.0})
    lab = m.entangling("lab")
    length, g = m.SCALES["lab"]
    assert lab["entangle_amplitude"] / length == pytest.approx(0.05)
    ag = (2 * math.pi * lab["entangle_freq"]) ** 2 * lab["entangle_amplitude"] / g
    assert ag == pytest.approx((2 * math.pi * 10) ** 2 * 0.05 / 10)
    assert lab["entangle_duration"] * lab["entangle_freq"] == pytest.approx(50)
    # the laboratory's drive: 25 mm at 5 Hz is l/2 at a/g 2.5 for 50 mm rods
    assert m.drive_freq(0.5, 2.5, 0.05, 9.81) == pytest.approx(4.985, abs=1e-3)
    assert m.throw_height(0.5, 2.5) == pytest.approx((0.025 * 2 * math.pi * 4.985) ** 2 / (9.81 * 0.05), rel=1e-3)
    # brackets: last alpha that fails, first that holds; beyond the alphas run; non-monotone said
    rows = lambda k, n: [{"ok": i < k} for i in range(n)]  # noqa: E731
    b = m.bracket({25: rows(0, 3), 50: rows(1, 3), 100: rows(3, 3), 200: rows(3, 3)}, lambda r: r["ok"])
    assert (b["lo"], b["hi"], b["text"]) == (50, 100, "50-100")
    assert b["counts"][50] == (1, 3)
    assert m.bracket({25: rows(3, 3), 50: rows(3, 3)}, lambda r: r["ok"])["text"] == "below 25"
    assert m.bracket({25: rows(0, 3), 50: rows(1, 3)}, lambda r: r["ok"])["text"] == "above 50"
    b = m.bracket({25: rows(3, 3), 50: rows(0, 3), 100: rows(3, 3)}, lambda r: r["ok"])
    assert b["text"] == "50-100 (not monotone)" and not b["monotone"]


def test_the_study_keeps_a_finished_simulation_whose_analysis_refused_and_not_a_stopped_one(tmp_path):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import alpha_star_controls as m

    summary = {"n_rods": 135, "a_over_g": 2.5, "largest_cluster_fraction": 0.03, "height_kept": 0.04,
               "persistence": 0.0, "rods_left": 0.9, "contacts_per_rod": 0.5, "stable": False,
               "max_penetration_over_d": 0.01, "freq": 5.0, "parameters": {"duration": 10.0},
               "landed": {"height_kept": 0.037, "largest_cluster_fraction": 0.03, "persistence": 0.0, "stable": False}}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    refused = {"id": "p", "status": "error: no voxel of the grid lies inside the packing", "cv_e": None}
    row = m.salvage(refused, tmp_path)
    assert row["status"] == "ok" and row["analysis"].startswith("error: no voxel")
    assert row["height_kept_landed"] == 0.037 and row["stable_landed"] is False and row["cycles_tested"] == 50
    assert row["cv_e"] is None
    stopped = {"id": "p", "status": "SimulationBlowUp: simulation blew up at step 3"}
    assert m.salvage(stopped, tmp_path) is stopped  # a stopped run's results are not made up
    assert m.salvage(refused, tmp_path / "missing") is refused  # nor a run that never finished
