"""Entanglement over time and the distributions of the fields (the transition's measures)."""

import csv
import json

import numpy as np
import pytest

from rodwarp.analysis import power_law_fit


@pytest.mark.parametrize("gamma", [0.8, 2.0, 2.5, 3.5])
def test_power_law_fit_recovers_the_exponent_and_range_of_a_power_law(gamma):
    rng = np.random.default_rng(1)
    u = rng.random(5000)
    if gamma > 1:
        law = (1.0 - u) ** (-1.0 / (gamma - 1.0))  # p(x) ~ x^-gamma for x >= 1
    else:  # p(x) ~ x^-gamma on [1, 1e4] (a shallow law needs an upper cut-off)
        law = ((1e4 ** (1 - gamma) - 1) * u + 1) ** (1 / (1 - gamma))
    body = rng.uniform(0.1, 1.0, 5000)  # not a power law below x_min = 1
    fit = power_law_fit(np.concatenate([law, body]))
    assert fit["gamma"] == pytest.approx(gamma, abs=0.1)
    assert abs(fit["gamma"] - gamma) < 4 * fit["gamma_err"]
    assert 0.9 < fit["xmin"] < 2.0 and fit["xmax"] > 10 ** (0.8 * np.log10(law.max()))
    assert fit["accepted"] and fit["decades"] > 1.0 and fit["note"] == ""


def test_power_law_fit_finds_no_steep_law_in_an_exponential_sample():
    rng = np.random.default_rng(2)
    fit = power_law_fit(rng.exponential(1.0, 10000))
    # the only power law in an exponential density is its flat start (gamma ~ 0, x << 1)
    assert fit["gamma"] < 0.3 and fit["xmax"] < 0.5
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
