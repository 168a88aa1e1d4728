"""scripts/grid_estimate.py: the schedule of a sweep whose tests wait for their donor."""

import csv
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import grid_estimate as ge  # noqa: E402


def test_tests_wait_for_their_donor():
    # two workers: donor A (10 s) with two tests of 5 s, donor B (3 s) with one of 1 s; B's test
    # runs at 3-4, A's two tests only from 10, side by side
    assert ge.dependent_makespan([(10, [5, 5]), (3, [1])], 2) == 15
    # one worker: everything in a row
    assert ge.dependent_makespan([(10, [5, 5]), (3, [1])], 1) == 24
    # without dependents it is a plain list schedule in the given order
    assert ge.dependent_makespan([(10, []), (4, []), (4, [])], 2) == ge.makespan([10, 4, 4], 2) == 10


def test_branched_rows_cost_their_test_and_no_share_drops_them(tmp_path):
    path = tmp_path / "results.csv"
    rows = [{"alpha": 25, "gravity": 0.5, "freq": 1, "static_load": 0, "wall_s": 30, "status": "ok",
             "entangled_from": ""},
            {"alpha": 25, "gravity": 0.5, "freq": 10, "static_load": 0, "wall_s": 12, "status": "ok",
             "entangled_from": "alpha25_freq1_g0.5_F0_seed0"}]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    c = ge.point_costs([path])
    assert c[(25.0, 0.5, 1.0)][0] == 30 and c[(25.0, 0.5, 1.0)][3] is False
    assert c[(25.0, 0.5, 10.0)][0] == 12 and c[(25.0, 0.5, 10.0)][3] is True
    assert (25.0, 0.5, 10.0) not in ge.point_costs([path], shared=False)
    with pytest.raises(SystemExit):
        ge.main(["--help"])
