"""The sag rule's one definition: the self-weight sag of a simply supported rod, 5 q l^4 / (384 E I)
with q = rho A g_eff, in diameters (issue 48). The figures the docs quote are computed here."""

from __future__ import annotations

import math

import pytest

from rodwarp.experiments import RIGID_SAG, ProtocolParams, rod_model_rule
from rodwarp.experiments._params import _sag_over_d


def _formula(alpha, length, g, young=200e9, density=7850.0):
    d = length / alpha
    q = density * math.pi * d**2 / 4 * g
    EI = young * math.pi * d**4 / 64
    return 5 * q * length**4 / (384 * EI) / d


def test_defaults_are_steel():
    p = ProtocolParams()
    assert (p.young, p.density) == (200e9, 7850.0)


def test_lab_alpha_200_sag_is_the_simply_supported_figure():
    # the laboratory's alpha-200 steel rods: l = 50 mm, d = 0.25 mm, g = 9.81 m/s^2
    p = ProtocolParams(protocol="lab", alpha=200, length=0.05, gravity=9.81)
    assert p.diameter == pytest.approx(0.25e-3)
    rule = rod_model_rule(p)
    assert rule["sag_over_d"] == pytest.approx(_formula(200, 0.05, 9.81), rel=1e-12)
    assert rule["sag_over_d"] == pytest.approx(0.0321, abs=5e-5)  # "0.032 d" in the docs
    assert rule["rod_model"] == "elastic"
    # a cantilever of the same rod, q l^4 / (8 E I), is 9.6 times as much: 0.31 d, not the rule's figure
    assert rule["sag_over_d"] * 384 / 40 == pytest.approx(0.308, abs=1e-3)


@pytest.mark.parametrize("kw, quoted", [
    (dict(protocol="lab", alpha=333, length=0.05, gravity=9.81), 0.148),   # experiments.md: "0.15 d"
    (dict(alpha=100, gravity=0.5), 0.0041),                               # performance.md: "0.004 d"
    (dict(alpha=50, gravity=10.0), 0.0102),                               # transition.md: "0.010 d"
    (dict(alpha=300, gravity=10.0), 2.21),                                # verdict.md: "2.2 d"
])
def test_quoted_sags(kw, quoted):
    p = ProtocolParams(**kw)
    assert _sag_over_d(p) == pytest.approx(_formula(p.alpha, p.length, p.gravity), rel=1e-12)
    assert _sag_over_d(p) == pytest.approx(quoted, rel=0.01)


def test_paper_rods_rigid_up_to_alpha_134_at_g_half():
    # protocol.md: "rigid for the paper's steel rods up to alpha = 134 at g = 0.5 m/s^2"
    assert rod_model_rule(ProtocolParams(alpha=134, gravity=0.5))["rod_model"] == "rigid"
    assert rod_model_rule(ProtocolParams(alpha=135, gravity=0.5))["rod_model"] == "elastic"
    assert _sag_over_d(ProtocolParams(alpha=134, gravity=0.5)) < RIGID_SAG < _sag_over_d(
        ProtocolParams(alpha=135, gravity=0.5))
