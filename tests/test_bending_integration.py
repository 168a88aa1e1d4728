"""Bending integration where rods touch: symplectic Euler pumps energy, implicit Euler does not.

The fixture (tests/data/pumping_pile.npz, scripts/make_pumping_fixture.py) is the paper's
protocol at alpha 200, g = 0.5, 300 rods, at the end of entangling: 78 J of kinetic and
93 J of bending energy. The stability test's control (side walls removed, a 1 mm floor
drive) can supply almost none, so the pile's mechanical energy can only fall.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from rodwarp.experiments import _protocol as protocol
from rodwarp.rodset import RodSet
from rodwarp.sim import State

FIXTURE = Path(__file__).parent / "data" / "pumping_pile.npz"


def pile(bending: str):
    with np.load(FIXTURE) as z:
        info = json.loads(str(z["meta"]))
        state_arrays = {k[6:]: z[k] for k in z.files if k.startswith("state_")}
        rods = RodSet(z["rods_points"], z["rods_offsets"], z["rods_radii"], box=z["rods_box"])
    p = dict(info["parameters"])
    p.pop("device", None)
    params = protocol.ProtocolParams(**p)
    model, solver, _ = protocol._build(params, rods, "cpu", "elastic")
    solver.bending = bending
    state = model.state()
    state.load_numpy(state_arrays)
    points = solver.contacts()
    points.load_numpy(state_arrays)  # the fixture's warm start
    stage = protocol.plan(params)[1]
    control = stage.control(model, info["stage_t0"])
    return solver, state, points, control, info["stepper"]


def mechanical(solver, state) -> float:
    e = solver.energy(state)
    return e["kinetic"] + e["bending"] + e["twist"] + e["stretching"]


def run(bending: str, steps: int):
    solver, a, points, control, st = pile(bending)
    b = State(solver.model)
    vmax, prev, ov = st["vmax"], st["dt"], st["overlap"]
    energy, thetas = [mechanical(solver, a)], []
    for _ in range(steps):
        dt = solver.adaptive_dt(control, vmax, prev, overlap=ov)
        info, dt, _ = solver.adaptive_step(a, b, control, points, dt)
        a, b = b, a
        vmax, prev, ov = info.max_speed, dt, info.max_overlap
        energy.append(mechanical(solver, a))
        thetas.append(info.theta)
    return np.array(energy), np.array(thetas), a


@pytest.mark.skipif(not FIXTURE.exists(), reason="tests/data/pumping_pile.npz missing")
def test_symplectic_bending_pumps_energy_into_a_dense_pile():
    """The former default: symplectic bending at a third of its stability bound. With nothing
    to supply it, the pile's kinetic + elastic energy more than doubles within 80 steps."""
    with pytest.warns(UserWarning, match="pump energy"):
        energy, thetas, _ = run("explicit", 80)
    assert np.all(thetas == 0.0)
    assert 150.0 < energy[0] < 200.0
    assert energy.max() > 2.0 * energy[0]


@pytest.mark.skipif(not FIXTURE.exists(), reason="tests/data/pumping_pile.npz missing")
def test_auto_bends_touching_rods_implicitly_and_the_energy_decays():
    energy, thetas, state = run("auto", 80)
    assert np.all(thetas == 1.0)  # the rods touch: implicit
    assert energy.max() <= energy[0] * (1 + 1e-9)
    assert energy[-1] < 0.1 * energy[0]


def test_a_contact_free_rod_still_bends_symplectically_below_its_bound():
    """Nothing to touch: symplectic bending conserves energy and stays the choice."""
    from rodwarp.sim import STEEL, Model, RodSolver
    from rodwarp.testing.scenes import straight_rod

    rods = RodSet.from_polylines([straight_rod((0, 0, 0), (1, 0, 0), 1.0, 0.005)], 0.005)
    model = Model(rods, STEEL, gravity=(0, 0, 0), rod_contacts=False)
    solver = RodSolver(model)
    eb = solver.explicit_bending_dt()
    assert solver.theta_for(0.5 * eb) == 0.0 and solver.theta_for(0.9 * eb) == 1.0
    assert solver.theta_for(0.5 * eb, touching=True) == 1.0
