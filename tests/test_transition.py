"""Entanglement over time and the distributions of the fields (the transition's measures)."""

import csv
import json

import numpy as np
import pytest

from rodwarp.analysis import power_law_fit


@pytest.mark.parametrize("gamma", [2.0, 2.5, 3.5])
def test_power_law_fit_recovers_the_exponent_of_a_power_law_tail(gamma):
    rng = np.random.default_rng(1)
    tail = (1.0 - rng.random(5000)) ** (-1.0 / (gamma - 1.0))  # p(x) ~ x^-gamma for x >= 1
    body = rng.uniform(0.1, 1.0, 5000)  # not a power law below x_min = 1
    fit = power_law_fit(np.concatenate([tail, body]))
    assert fit["gamma"] == pytest.approx(gamma, abs=0.1)
    assert abs(fit["gamma"] - gamma) < 4 * fit["gamma_err"] + 0.02
    assert 0.9 < fit["xmin"] < 2.0
    assert fit["decades"] > 1.0 and fit["note"] == ""


def test_power_law_fit_says_when_the_tail_is_too_narrow():
    rng = np.random.default_rng(2)
    fit = power_law_fit(rng.exponential(1.0, 10000))  # no power law: the 'tail' spans < 1 decade
    assert fit["decades"] < 1.0 and "too narrow" in fit["note"]
    assert power_law_fit(np.ones(10)) is None  # too few samples


def test_cv_e_over_time_equals_rodwarp_analyze_on_the_same_frame(tmp_path):
    from rodwarp.analysis import analyze
    from rodwarp.experiments import ProtocolParams, run_protocol

    p = ProtocolParams(alpha=25, n_rods=30, entangle_duration=0.2, duration=0.2, save_every=0.1, fields_every=0.1,
                       checkpoint_every=10.0, device="cpu")
    s = run_protocol(p, tmp_path / "run", progress=False)
    rows = list(csv.DictReader(open(tmp_path / "run" / "metrics.csv")))
    with_fields = [r for r in rows if r["cv_e"] != ""]
    assert len(with_fields) == len(rows)  # every sample starts a 0.1 s interval
    a = analyze(tmp_path / "run" / "final.npz", tmp_path / "an")
    assert float(rows[-1]["cv_e"]) == pytest.approx(a["cv_e"], rel=1e-12)
    assert float(rows[-1]["mean_e"]) == pytest.approx(a["mean_e"], rel=1e-12)
    assert s["cv_e_final"] == pytest.approx(a["cv_e"], rel=1e-12)
    assert json.load(open(tmp_path / "run" / "summary.json"))["fields_wall_s"] > 0
    # the analysis reports the tails of p(e) and p(c) too
    assert set(a["power_law"]) == {"e", "c"}


def test_fields_every_must_be_a_multiple_of_save_every():
    from rodwarp.errors import RodwarpError
    from rodwarp.experiments import ProtocolParams

    with pytest.raises(RodwarpError, match="whole multiple of --save-every"):
        ProtocolParams(save_every=0.1, fields_every=0.25).validate()
    with pytest.raises(RodwarpError, match="fields-every"):
        ProtocolParams(fields_every=-1.0).validate()
    ProtocolParams(save_every=0.1, fields_every=0.5).validate()
    ProtocolParams(fields_every=0.0).validate()
