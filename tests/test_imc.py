"""The IMC contact law (DisMech's, the paper's) against its own closed-form answers.

* a rod resting on the floor settles at the penalty's equilibrium gap, F(g) = the load;
* a rod resting across two fixed rods does the same at its two rod-rod contacts;
* on an incline below the friction angle a rod does not stick: it creeps at the speed where the
  smoothed friction balances the load, (2 nu / 15) artanh(tan(theta) / mu);
* above it, it slides at g (sin(theta) - mu cos(theta)).

The exact law stays the default, and every other test runs with it.
"""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from rodwarp.errors import RodwarpError
from rodwarp.rodset import RodSet
from rodwarp.sim import STEEL, ContactLaw, Model, ModelBuilder, RodSolver, run
from rodwarp.sim.contact_law import imc_creep_speed, imc_force
from rodwarp.testing.scenes import straight_rod, tilted_gravity

G = 9.81
R = 0.01
MU = 0.4
MODELS = ("elastic", "rigid")


def rod_on_incline(theta_deg, rod_model, nu=1e-3, mu=MU):
    """A 1 m steel rod along the slope's x, lying on the floor, spin locked (IMC's centreline
    friction), gravity tilted by ``theta_deg``."""
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, R), (1, 0, 0), 1.0, R)], R)
    builder = ModelBuilder(rods, STEEL, gravity=tilted_gravity(G, theta_deg), mu=mu, rod_contacts=False, rod_model=rod_model,
                           rolling=False, contact_law=ContactLaw("imc", nu=nu))
    builder.add_plane((0, 0, 1), 0.0, mu=mu, name="floor")
    model = builder.finalize()
    return model


def mean_velocity(model, duration, dt=1e-3):
    """Times and mean x velocity of the vertices, every step, converged sweeps (the stiff smoothed
    friction of an elastic rod at nu = 1e-4 m/s takes about 2000: docs/physics.md)."""
    solver = RodSolver(model, iterations=5000, tolerance=1e-12)
    ts, vs = [], []
    run(solver, model.state(), duration, dt,
        callback=lambda s, i: (ts.append(s.time), vs.append(s.v.numpy()[:, 0].mean())))
    return np.array(ts), np.array(vs)


def equilibrium_gap(load, law):
    return brentq(lambda g: imc_force(g, law.delta, law.stiffness) - load, -law.delta, law.delta, xtol=1e-16)


def test_defaults_are_the_exact_law_and_the_papers_delta():
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, R), (1, 0, 0), 1.0, R)], R)
    assert Model(rods, STEEL).contact_law.name == "exact"
    m = Model(rods, STEEL, gravity=(0, 0, -G), contact_law="imc")
    law = m.contact_law
    assert law.delta == pytest.approx(0.1 * 2 * R)  # d / 10
    weight = STEEL.density * math.pi * R**2 * 1.0 * G
    assert law.stiffness == pytest.approx(1000 * weight / law.delta)
    assert m.contact_distance >= law.delta  # pairs are found where the penalty acts
    with pytest.raises(RodwarpError, match="exact or imc"):
        ContactLaw("hertz")
    with pytest.raises(RodwarpError, match="nu must be a positive"):
        ContactLaw("imc", nu=0.0)


def test_penalty_force_is_dismechs():
    # DisMech's floor force: 2 k v log(1 + v) / (K1 (1 + v)) with v = exp(-K1 g), K1 = 15 / delta
    delta, k = 1e-3, 2e5
    g = np.linspace(-2 * delta, 0.99 * delta, 50)
    v = np.exp(-15 / delta * g)
    assert np.allclose(imc_force(g, delta, k), 2 * k * v * np.log1p(v) / (15 / delta * (1 + v)), rtol=1e-12)
    assert imc_force(1.01 * delta, delta, k) == 0.0  # nothing beyond the distance tolerance


@pytest.mark.parametrize("rod_model", MODELS)
def test_rod_on_the_floor_settles_at_the_penalty_equilibrium_gap(rod_model):
    model = rod_on_incline(0.0, rod_model)
    law = model.contact_law
    solver = RodSolver(model, iterations=400, tolerance=1e-12)
    state = run(solver, model.state(), 0.5, 1e-3)
    gaps = state.x.numpy()[:, 2] - R
    weight = STEEL.density * math.pi * R**2 * 1.0 * G
    if rod_model == "rigid":
        # two end contacts carry half the weight each: the gap solves F(g) = m g / 2
        assert np.allclose(gaps, equilibrium_gap(weight / 2, law), rtol=1e-6, atol=0)
    else:
        # the vertex forces of a bending rod are statically indeterminate; together they carry its weight
        assert imc_force(gaps, law.delta, law.stiffness).sum() == pytest.approx(weight, rel=1e-6)
        assert 0 < gaps.min() < gaps.max() < law.delta  # the smoothed law holds the rod just above the floor
    assert np.abs(state.v.numpy()).max() < 1e-9


def test_rod_across_two_fixed_rods_rests_at_the_rod_rod_equilibrium_gap():
    # two parallel rods along y, pinned, at x = +-0.3; a rigid rod along x lies across them
    lower = [straight_rod((x, 0.0, 0.0), (0, 1, 0), 1.0, R, n_vertices=2) for x in (-0.3, 0.3)]
    top = straight_rod((0.0, 0.0, 2 * R + 1e-4), (1, 0, 0), 1.0, R, n_vertices=2)
    rods = RodSet.from_polylines([*lower, top], R)
    model = Model(rods, STEEL, gravity=(0, 0, -G), mu=MU, rod_model="rigid", rolling=False, pinned=np.arange(4),
                  contact_law="imc")
    law = model.contact_law
    solver = RodSolver(model, iterations=400, tolerance=1e-12)
    state = run(solver, model.state(), 0.5, 1e-3)
    z_top = state.x.numpy()[4:, 2].mean()
    weight = STEEL.density * math.pi * R**2 * 1.0 * G
    assert z_top - 2 * R == pytest.approx(equilibrium_gap(weight / 2, law), rel=1e-6)


@pytest.mark.parametrize("rod_model", MODELS)
@pytest.mark.parametrize("nu", [1e-4, 1e-3, 1e-2])
def test_rod_on_an_incline_below_the_friction_angle_creeps_at_the_smoothed_law_speed(nu, rod_model):
    theta = 10.0  # tan(10 deg) / 0.4 = 0.44 of the friction limit
    t, v = mean_velocity(rod_on_incline(theta, rod_model, nu=nu), 0.3)
    creep = imc_creep_speed(math.tan(math.radians(theta)) / MU, nu)
    assert v[-1] == pytest.approx(creep, rel=1e-4)
    assert np.allclose(v[-50:], v[-1], rtol=1e-6)  # steady: a creep, not an acceleration


@pytest.mark.parametrize("rod_model", MODELS)
def test_rod_on_an_incline_above_the_friction_angle_slides_at_g_sin_minus_mu_cos(rod_model):
    theta = 30.0
    t, v = mean_velocity(rod_on_incline(theta, rod_model), 0.5)
    th = math.radians(theta)
    # well above nu (full Coulomb friction), after the rod has settled onto the penalty (it
    # starts touching, above the law's equilibrium gap)
    late = (v > 10 * 1e-3) & (t > 0.25)
    a = np.polyfit(t[late], v[late], 1)[0]
    assert a == pytest.approx(G * (math.sin(th) - MU * math.cos(th)), rel=1e-6)


def test_the_exact_law_sticks_where_imc_creeps():
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, R), (1, 0, 0), 1.0, R)], R)
    builder = ModelBuilder(rods, STEEL, gravity=tilted_gravity(G, 10.0), mu=MU, rod_contacts=False, rolling=False)
    builder.add_plane((0, 0, 1), 0.0, mu=MU, name="floor")
    model = builder.finalize()
    t, v = mean_velocity(model, 0.3)
    assert abs(v[-1]) < 1e-10


# ----------------------------------------------------------------------------------------------
# the command line: --contact-law and its options
# ----------------------------------------------------------------------------------------------

TINY = ["--alpha", "20", "--n-rods", "12", "--entangle-duration", "0.02", "--duration", "0.02", "--save-every",
        "0.01", "--device", "cpu", "--quiet"]


def _one_error_line(capsys, args):
    from rodwarp.cli import main

    capsys.readouterr()
    rc = main([str(a) for a in args])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2 and len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


@pytest.mark.parametrize("args, fragment", [
    (["--contact-law", "hertz"], "--contact-law must be exact or imc"),
    (["--imc-nu", "1e-3"], "--imc-nu only applies with --contact-law imc"),
    (["--contact-law", "exact", "--imc-delta", "0.1"], "--imc-delta only applies with --contact-law imc"),
    (["--contact-law", "imc", "--imc-nu", "0"], "--imc-nu"),
    (["--contact-law", "imc", "--imc-delta", "3"], "in rod diameters"),
    (["--contact-law", "imc", "--imc-stiffness", "-5"], "--imc-stiffness"),
])
def test_bad_contact_law_options_are_refused_in_one_line(capsys, tmp_path, args, fragment):
    line = _one_error_line(capsys, ["simulate", *TINY, *args, "--out", tmp_path / "run"])
    assert fragment in line, line
    assert not (tmp_path / "run").exists()


def test_imc_run_records_its_law_and_locks_the_spin_unless_asked(capsys, tmp_path):
    import json

    from rodwarp.cli import main

    assert main(["simulate", *TINY, "--contact-law", "imc", "--imc-nu", "0.01", "--out", str(tmp_path / "a")]) == 0
    s = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert s["contact_law"]["name"] == "imc" and s["contact_law"]["nu_m_per_s"] == 0.01
    assert s["contact_law"]["delta_m"] == pytest.approx(0.1 * 1.0 / 20)  # d / 10 (l = 1 m, alpha 20)
    assert s["rolling"] is False  # DisMech's friction acts on the centreline
    capsys.readouterr()
    assert main(["simulate", *TINY, "--contact-law", "imc", "--rolling", "--out", str(tmp_path / "b")]) == 0
    assert "warning: --rolling with --contact-law imc" in capsys.readouterr().err
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["rolling"] is True
    assert main(["simulate", *TINY, "--out", str(tmp_path / "c")]) == 0
    s = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert s["contact_law"]["name"] == "exact" and s["rolling"] is True


def test_runs_written_before_the_contact_law_option_compare_equal_to_todays_defaults():
    from rodwarp.experiments._protocol import _comparable, _effective

    old = {"alpha": 50.0, "rolling": True, "seed": 0}  # a checkpoint of an older rodwarp
    new = {"alpha": 50.0, "rolling": None, "contact_law": None, "imc_nu": None, "seed": 0}
    assert _comparable(old) == _comparable(new)
    assert _comparable({**new, "contact_law": "exact"}) == _comparable(old)
    # an IMC run's default locks the spin: it differs from an old rolling run
    assert _comparable({**new, "contact_law": "imc"}) != _comparable(old)
    assert _effective({**new, "contact_law": "imc"})["rolling"] is False
