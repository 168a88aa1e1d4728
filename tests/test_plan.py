"""The run plan: the paper's protocol as stages, and a stage added in one place."""

import csv

import pytest

from rodwarp.errors import RodwarpError
from rodwarp.experiments import ProtocolParams, run_protocol
from rodwarp.experiments import Stage, plan
from rodwarp.experiments._plan import frames
from rodwarp.experiments.protocols.paper import ENTANGLE, SIDE_WALLS, TEST

TINY = dict(alpha=20, n_rods=12, entangle_duration=0.05, duration=0.05, save_every=0.01, fields_every=0.0,
            checkpoint_every=0.02, device="cpu")


def test_the_papers_protocol_is_entangling_then_the_test():
    p = ProtocolParams(alpha=100, freq=10)
    stages = plan(p)
    assert [s.name for s in stages] == [ENTANGLE, TEST]
    ent, test = stages
    assert (ent.duration, ent.amplitude, ent.freq, ent.walls_out) == (5.0, 0.05, 10.0, ())
    assert (test.duration, test.amplitude, test.freq, test.walls_out) == (5.0, 0.001, 10.0, SIDE_WALLS)
    assert test.test and ent.keep and not test.keep
    assert [s.name for s in plan(ProtocolParams(entangle_duration=0.0))] == [TEST]
    assert frames(stages, 0.1) == 1 + 51 + 51


def test_a_plan_with_the_container_lifted_away_before_the_test(tmp_path):
    params = ProtocolParams(**TINY)
    ent, test = plan(params)
    # one stage added in one place: the side walls and lid taken away, the packing left to stand or spread
    lifted = (ent, Stage("lift", 0.03, walls_out=SIDE_WALLS, title="container lifted"), test)
    s = run_protocol(params, tmp_path / "run", progress=False, stages=lifted)
    with open(tmp_path / "run" / "metrics.csv") as fh:
        rows = list(csv.DictReader(fh))
    order = [r["stage"] for r in rows]
    assert order == sorted(order, key=[ENTANGLE, "lift", TEST].index)  # the stages in the plan's order
    assert order.count("lift") == 3 and order.count(TEST) == 5
    assert set(s["dt"]) == {ENTANGLE, "lift", TEST}
    # the verdict measures the test from its own start, after the lift
    assert s["test_start"]["time"] == pytest.approx(0.08)
    # the same test after entangling alone starts 0.03 s earlier: the lift stage ran
    s0 = run_protocol(params, tmp_path / "plain", progress=False)
    assert s0["test_start"]["time"] == pytest.approx(0.05)


def test_a_plan_needs_one_test_and_unique_names(tmp_path):
    params = ProtocolParams(**TINY)
    ent, test = plan(params)
    with pytest.raises(RodwarpError, match="exactly one test stage"):
        run_protocol(params, tmp_path / "a", progress=False, stages=(ent,))
    with pytest.raises(RodwarpError, match="unique"):
        run_protocol(params, tmp_path / "b", progress=False, stages=(ent, ent, test))
