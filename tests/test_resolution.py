"""The resolution rule of elastic rods (issue 45; docs/physics.md, "Resolution of elastic rods").

The rule picks the fewest vertices whose discrete self-weight sag is within 0.01 d of the beam's
where every drive is quasi-static for the rods' bending. It rests on the discrete sag of
:func:`discrete_sag`; the engine's own sag of a rod lying across two frictionless rails at its
end vertices (a simply supported beam) is checked against it and against Euler-Bernoulli.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rodwarp.experiments import ProtocolParams
from rodwarp.experiments._params import (MAX_VERTICES, MIN_VERTICES, RIGID_SAG, beam_sag, discrete_sag,
                                         first_bending_frequency, rod_model_rule, rod_resolution,
                                         sag_discretisation_error)
from rodwarp.rodset import RodSet
from rodwarp.sim.model import Material, Model
from rodwarp.sim.solver import RodSolver, run
from rodwarp.testing.scenes import TEST_DENSITY, TEST_RADIUS, TEST_YOUNG, straight_rod

LAB_200 = ProtocolParams(protocol="lab", alpha=200, length=0.05, gravity=9.81, freq=5, amplitude=0.025)


def test_discrete_sag_of_three_vertices_is_six_fifths_of_the_beam():
    # one free vertex: K = 4 E I / h^3 against its weight q h, h = l / 2: w = q l^4 / (64 E I),
    # against the beam's 5 q l^4 / (384 E I): 384 / 320 = 1.2
    assert discrete_sag(3)[1] == pytest.approx(1.0 / 64.0, rel=1e-12)
    assert sag_discretisation_error(3) == pytest.approx(0.2, rel=1e-12)


def test_discrete_sag_converges_at_second_order():
    errs = np.array([sag_discretisation_error(n) for n in (5, 9, 17)])  # edges halved each time
    assert np.all(np.diff(errs) < 0)
    assert errs[0] / errs[1] == pytest.approx(4.0, rel=0.15)
    assert errs[1] / errs[2] == pytest.approx(4.0, rel=0.1)


def settle_on_rails(n_vertices: int) -> np.ndarray:
    """Vertex deflections (m) of a rod of ``n_vertices`` lying across two fixed, frictionless
    rails under its end vertices, settled under gravity: a simply supported beam."""
    r, L = TEST_RADIUS, 1.0
    rails = [straight_rod((0, -0.5 * L, 0), (1, 0, 0), 0.2, r, n_vertices=2),
             straight_rod((0, 0.5 * L, 0), (1, 0, 0), 0.2, r, n_vertices=2)]
    top = straight_rod((0, 0, 2 * r), (0, 1, 0), L, r, n_vertices=n_vertices)
    rods = RodSet.from_polylines(rails + [top], r)
    mat = Material(young=TEST_YOUNG, density=TEST_DENSITY)
    model = Model(rods, mat, gravity=(0, 0, -9.81), mu=0.0, damping=30.0, pinned=np.arange(4))
    solver = RodSolver(model, iterations=60, tolerance=0.0)
    state = run(solver, model.state(), 1.5, 1e-3)
    z = state.positions()[4:, 2]
    return 0.5 * (z[0] + z[-1]) - z  # deflection below the supports' chord


@pytest.mark.parametrize("n", [3, 4, 6])
def test_engine_sag_across_two_rails_is_the_discrete_sag_the_rule_uses(n):
    q = TEST_DENSITY * np.pi * TEST_RADIUS**2 * 9.81
    EI = TEST_YOUNG * np.pi * TEST_RADIUS**4 / 4
    w = settle_on_rails(n)
    predicted = discrete_sag(n) * q / EI
    beam = beam_sag(np.linspace(0, 1, n)) * q / EI
    mid = 5 * q / (384 * EI)
    # the engine's rod is the discrete model the rule solves (within 1% of the midspan sag) ...
    assert np.abs(w - predicted).max() < 0.01 * mid
    # ... and differs from the beam by the error the rule charges it
    assert np.abs(w - beam).max() / mid == pytest.approx(sag_discretisation_error(n), abs=0.01)


def test_the_rule_takes_three_vertices_for_the_labs_alpha_200_rods():
    rule = rod_resolution(LAB_200)
    assert rod_model_rule(LAB_200)["rod_model"] == "elastic"
    assert rule["quasi_static"]  # 5 Hz against a first bending mode near 450 Hz
    assert first_bending_frequency(LAB_200) == pytest.approx(449, rel=0.01)
    assert rule["vertices"] == 3 and LAB_200.n_vertices == 3
    assert rule["sag_error_over_d"] <= RIGID_SAG


def test_the_rule_keeps_ten_vertices_where_the_drive_reaches_the_bending_modes():
    # the paper's protocol at alpha 200: l = 1 m, first bending mode 22 Hz, drives at 10 Hz
    p = ProtocolParams(alpha=200)
    assert not rod_resolution(p)["quasi_static"]
    assert p.n_vertices == MAX_VERTICES


def test_the_rule_refines_where_the_sag_grows_and_an_explicit_count_wins():
    # a quasi-static scene whose rods sag more: 0.25 d needs err <= 0.04 (6 vertices)
    soft = dataclasses.replace(LAB_200, young=LAB_200.young * 0.128)
    rule = rod_resolution(soft)
    assert rule["quasi_static"]
    n = rule["vertices"]
    assert MIN_VERTICES < n <= MAX_VERTICES
    assert sag_discretisation_error(n) * rod_model_rule(soft)["sag_over_d"] <= RIGID_SAG
    assert sag_discretisation_error(n - 1) * rod_model_rule(soft)["sag_over_d"] > RIGID_SAG
    assert dataclasses.replace(LAB_200, vertices=7).n_vertices == 7


def test_rigid_rods_keep_the_packings_ten_vertex_polylines():
    p = ProtocolParams(protocol="lab", alpha=100, length=0.05, gravity=9.81, freq=5, amplitude=0.025)
    assert rod_model_rule(p)["rod_model"] == "rigid"
    assert p.n_vertices == MAX_VERTICES


def test_a_checkpoint_from_before_the_rule_resumes_with_what_it_ran_with():
    from dataclasses import asdict

    from rodwarp.experiments._protocol import _effective

    old = asdict(ProtocolParams())
    old.pop("steps_per_period")  # written before the option existed: 40 steps a period
    old["vertices"] = 10
    assert _effective(old) == _effective(asdict(ProtocolParams(steps_per_period=40)))
    assert _effective(old) != _effective(asdict(ProtocolParams()))  # today's default is 20
    lab = {**asdict(LAB_200), "vertices": 10}
    lab.pop("steps_per_period")
    assert _effective(lab) != _effective(asdict(dataclasses.replace(LAB_200, steps_per_period=40)))  # 3 vertices now
    assert _effective(lab) == _effective(asdict(dataclasses.replace(LAB_200, steps_per_period=40, vertices=10)))

