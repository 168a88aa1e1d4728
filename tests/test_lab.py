"""The laboratory protocol (docs/experiments.md) against what each stage must do: the pour
fills the cylinder without overlaps, a single rod is left lying on the floor at rest when the
container is lifted, the piston reaches each strain and holds it, and the plate moves as asked."""

import csv
import json
import math

import numpy as np
import pytest
import zarr

from rodwarp.errors import RodwarpError
from rodwarp.experiments import ProtocolParams, run_protocol
from rodwarp.experiments import plan
from rodwarp.experiments.protocols.lab import FLOOR, LIFT, PISTON, POUR, SHAKE, TUBE, PressTo, lab_plan

# steel rods of the paper's experiments' scale: l = 5 cm, real gravity
LAB = dict(protocol="lab", alpha=20, length=0.05, gravity=9.81, freq=5.0, amplitude=0.025, save_every=0.05,
           fields_every=0.0, checkpoint_every=0.5, device="cpu")


def _rows(run):
    with open(run / "metrics.csv") as fh:
        return list(csv.DictReader(fh))


def _frame(run, k):
    g = zarr.open_group(str(run / "trajectory.zarr"), mode="r")
    return np.asarray(g["positions"][k]), float(g["time"][k])


def test_the_lab_plan_pours_presses_lifts_and_shakes():
    p = ProtocolParams(**LAB, strains=(0.0, 0.05, 0.1), duration=2.0)
    stages = lab_plan(p)
    assert [s.name for s in stages] == [POUR, "press0", "press0.05", "press0.1", LIFT, SHAKE]
    assert plan(p) == stages
    assert [s.motion for s in stages[1:4]] == [PressTo(0.0, 0.0), PressTo(0.0, 0.05), PressTo(0.05, 0.1)]
    assert [s.name for s in stages if s.test] == [SHAKE]
    assert stages[0].walls_out == (PISTON,) and stages[-1].walls_out == (TUBE, PISTON)
    assert stages[-1].moving == (FLOOR,) and all(s.moving == (PISTON,) for s in stages[1:4])
    # without shaking the lifted packing is the test; the paper's protocol is unchanged
    assert [s.name for s in lab_plan(ProtocolParams(**{**LAB, "duration": 0.0}))] == [POUR, LIFT]
    assert lab_plan(ProtocolParams(**{**LAB, "duration": 0.0}))[-1].test
    assert [s.name for s in plan(ProtocolParams())] == ["entangle", "stability"]


def test_the_cylinder_holds_the_rods_that_fill_it_to_the_fill_height():
    p = ProtocolParams(**LAB)
    # 4 (Rc/l)^2 (H/l) 5.4 alpha at Rc = H = 1 l
    assert p.rods == round(4 * 5.4 * 20)
    assert ProtocolParams(**LAB, container_radius=1.5, fill_height=2.0).rods == round(4 * 2.25 * 2 * 5.4 * 20)
    assert ProtocolParams(**LAB, n_rods=7).rods == 7
    # the pour column is dilute: phi alpha = 2 in it
    v_rod = math.pi / 4 * p.diameter**2 * p.length
    phi = p.rods * v_rod / (math.pi * p.length**2 * p.pour_height())
    assert phi * p.alpha == pytest.approx(2.0)


def test_the_pour_fills_the_cylinder_without_overlaps(tmp_path):
    p = ProtocolParams(**LAB, n_rods=30, pour_duration=0.6, duration=0.0, lift_duration=0.05)
    s = run_protocol(p, tmp_path / "run", progress=False)
    rows = _rows(tmp_path / "run")
    pour = [k for k, r in enumerate(rows) if r["stage"] == POUR]
    x0, _ = _frame(tmp_path / "run", 0)
    x, t = _frame(tmp_path / "run", pour[-1])
    assert t == pytest.approx(0.6)
    r = 0.5 * p.diameter
    rc = p.container_radius * p.length
    slop = 0.02 * p.diameter
    # released above the floor inside the cylinder, fallen onto the floor, every rod still inside
    assert x0[:, 2].min() > r and np.hypot(x0[:, 0], x0[:, 1]).max() <= rc - r
    assert np.hypot(x[:, 0], x[:, 1]).max() <= rc - r + slop
    assert x[:, 2].min() >= r - slop
    assert x[:, 2].max() < 0.5 * x0[:, 2].max()
    assert max(float(rows[k]["max_penetration_over_d"]) for k in pour) < 0.02
    # settled: the kinetic energy has fallen by orders of magnitude from its peak in the fall
    ke = [float(rows[k]["kinetic_energy"]) for k in pour]
    assert ke[-1] < 1e-3 * max(ke)
    assert s["lab"]["pour"]["contacts_per_rod"] > 1.0


def test_the_lifted_container_leaves_a_single_rod_on_the_floor_at_rest(tmp_path):
    p = ProtocolParams(**LAB, n_rods=1, pour_duration=0.4, duration=0.0, lift_duration=0.3)
    s = run_protocol(p, tmp_path / "run", progress=False)
    fin = np.load(tmp_path / "run" / "final.npz")
    x, v = fin["points"], fin["velocities"]
    r = 0.5 * p.diameter
    assert x[:, 2] == pytest.approx(r, abs=0.02 * p.diameter)  # lying flat on the floor
    assert np.abs(v).max() < 1e-6
    assert s["lab"]["lift"]["largest_cluster_fraction"] == 1.0
    assert s["lab"]["lift"]["spread_over_container"] < 1.0  # it stayed where it lay


def test_the_piston_reaches_each_strain_and_holds_it(tmp_path):
    strains = (0.0, 0.05, 0.1)
    p = ProtocolParams(**LAB, n_rods=40, pour_duration=0.5, strains=strains, press_duration=0.2, duration=0.0,
                       lift_duration=0.05)
    s = run_protocol(p, tmp_path / "run", progress=False)
    res = s["lab"]["strains"]
    assert [e["strain"] for e in res] == list(strains)
    h0 = res[0]["height0"]
    rows = _rows(tmp_path / "run")
    for e in res:
        assert e["strain_reached"] == pytest.approx(e["strain"], abs=1e-9)
        assert e["piston_height"] == pytest.approx(h0 * (1 - e["strain"]), rel=1e-12)
        # the packing is under the piston (within the contact slop) and at rest when the hold ends
        assert e["packing_top"] <= e["piston_height"] + 0.02 * p.diameter
        assert e["max_speed"] < 1e-3
        held = [float(r["piston_height"]) for r in rows if r["stage"] == e["stage"]][-2:]  # the hold's samples
        assert held == pytest.approx([e["piston_height"]] * 2, rel=1e-12)
    # the piston is out before and after pressing
    assert all(r["piston_height"] == "" for r in rows if r["stage"] in (POUR, LIFT))
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["lab"]["strains"] == res
    # each pressed packing is kept, rods and contacts, to be analysed again: the rods under the
    # piston it was pressed by, and the contacts those rods make
    from rodwarp.rodset import load
    from rodwarp.rodset import detect_contacts

    for e in res:
        rods = load(tmp_path / "run" / e["rods"])
        assert e["rods"] == f"rods_{e['stage']}.npz"
        assert rods.n_rods == 40 and rods.units == "m" and rods.contacts is not None
        assert rods.attrs["strain"] == e["strain"] and rods.attrs["piston_height_m"] == e["piston_height"]
        assert rods.points[:, 2].max() <= e["piston_height"] + 0.02 * p.diameter
        assert len(rods.contacts) == pytest.approx(len(detect_contacts(rods)), abs=0.1 * len(rods.contacts) + 2)


def test_wall_mu_sets_the_cylinder_and_the_piston_only():
    from rodwarp.experiments.protocols.lab import lab_packing, lab_walls
    from rodwarp.sim import ModelBuilder

    p = ProtocolParams(**LAB, n_rods=5, wall_mu=0.0, mu=0.3)
    rods = lab_packing(p, "cpu")
    b = ModelBuilder(rods, mu=p.mu)
    lab_walls(b, p, rods)
    mus = {w.name: w.mu for w in b.walls}
    assert mus == {FLOOR: None, TUBE: 0.0, PISTON: 0.0}  # the plate takes the model's mu (0.3)
    lab_walls(b2 := ModelBuilder(rods, mu=p.mu), ProtocolParams(**LAB, n_rods=5), rods)
    assert {w.name: w.mu for w in b2.walls} == {FLOOR: None, TUBE: None, PISTON: None}


def test_the_shaken_plate_moves_as_asked():
    from rodwarp.experiments._protocol import _build
    from rodwarp.experiments.protocols.lab import lab_packing

    p = ProtocolParams(**LAB, n_rods=5, duration=1.0)
    rods = lab_packing(p, "cpu")
    model, solver, _ = _build(p, rods, "cpu", "rigid")
    shake = lab_plan(p)[-1]
    t0 = 1.3
    control = shake.control(model, t0)
    names = [w.name for w in model.walls]
    assert control.walls_in_place() == [FLOOR]
    assert control.moving.tolist() == [n == FLOOR for n in names]
    # amplitude 25 mm at 5 Hz, started at rest at the plate's lowest point (z = 0)
    z = lambda t: 0.025 * (1 - math.cos(2 * math.pi * 5.0 * (t - t0)))  # noqa: E731
    for t in np.linspace(t0, t0 + 0.4, 9):
        assert control.floor_height(t) == pytest.approx(z(t), abs=1e-15)
    assert control.floor_height(t0 + 0.1) == pytest.approx(0.05)  # the top, half a period on
    # what the kernels get: the floor displaced by the drive, its velocity the mean over the step
    dt = 1e-3
    w = solver._walls(control, t0 + 0.05, dt)
    assert w.drive_disp == pytest.approx(z(t0 + 0.05))
    assert w.drive_vel == pytest.approx((z(t0 + 0.051) - z(t0 + 0.05)) / dt)
    assert abs(float(solver._walls(control, t0, dt).drive_vel)) < 0.02  # starts from rest
    assert w.shift.numpy()[names.index(FLOOR)] == 1.0 and w.shift.numpy()[names.index(PISTON)] == 0.0
    # a/g of the experiments: 4 pi^2 f^2 A / g = 2.5
    assert p.a_over_g == pytest.approx(2.516, abs=1e-3)


def _inelastic_ball_on_plate(amplitude, freq, cycles, dt=1e-5, g=9.81):
    """A perfectly inelastic ball on a plate z_p = A (1 - cos 2 pi f t) (the lab's shaking):
    it leaves the plate when the plate's acceleration falls below -g, flies, and sticks where
    it lands. Returns t and the ball's height above the plate (m)."""
    w = 2 * math.pi * freq
    t = np.arange(0.0, cycles / freq + dt / 2, dt)
    zp = amplitude * (1 - np.cos(w * t))
    vp = amplitude * w * np.sin(w * t)
    z = np.zeros_like(t)
    zc, v, stuck = 0.0, 0.0, True
    for i in range(1, len(t)):
        if stuck and amplitude * w * w * math.cos(w * t[i]) < -g:
            stuck, v = False, vp[i - 1]
        if stuck:
            zc = zp[i]
        else:
            v -= g * dt
            zc += v * dt
            if zc <= zp[i]:
                zc, stuck = zp[i], True
        z[i] = zc
    return t, z - zp


def test_fig_1e_takes_the_landed_height_of_a_packing_the_plate_throws():
    from rodwarp.experiments.protocols.lab import landed_heights

    # at 5 Hz, 25 mm (a/g = 2.5) a ball resting 10 mm above the plate is thrown every cycle
    y0 = 0.01
    t, dz = _inelastic_ball_on_plate(0.025, 5.0, cycles=6)
    y = (y0 + dz) / y0
    step = round(0.025 / 1e-5)  # --save-every 0.025: 8 samples per cycle
    k, landed = landed_heights(t[::step], y[::step], 5.0)
    assert k.tolist() == [1, 2, 3, 4, 5, 6]
    # landed every cycle: the lowest height of each cycle is the height it rests at
    assert landed == pytest.approx(1.0, abs=1e-12)
    # a sample once per cycle at the plate's lowest point catches the ball in flight, ~4 y_c(0)
    once = y[:: round(0.2 / 1e-5)][1:]
    assert once.min() > 3.5 and once.max() < 5.0
    # samples too sparse to see the landing are not landed heights: one per cycle at that phase
    k1, l1 = landed_heights(t[:: round(0.2 / 1e-5)], y[:: round(0.2 / 1e-5)], 5.0)
    assert l1 == pytest.approx(once)


def test_too_few_samples_per_cycle_for_the_landed_height_are_flagged():
    from rodwarp.experiments.protocols.lab import landed_sampling_warning

    # 5 Hz: one sample per cycle is flagged, eight are not; a gentle drive (a/g < 1) never is
    assert "samples per cycle" in landed_sampling_warning(ProtocolParams(**{**LAB, "save_every": 0.2}))
    assert landed_sampling_warning(ProtocolParams(**{**LAB, "save_every": 0.025})) is None
    assert landed_sampling_warning(ProtocolParams(**{**LAB, "save_every": 0.2, "amplitude": 0.005})) is None


@pytest.mark.parametrize("kw, message", [
    (dict(strains=(0.1,)), r"--strains does not apply with --protocol paper \(only with --protocol lab\)"),
    (dict(protocol="lab", box=(2.0, 2.0, 2.0)), "--box does not apply with --protocol lab"),
    (dict(protocol="lab", strains=(0.1, 0.05)), "must not decrease"),
    (dict(protocol="lab", strains=(0.6,)), "--strains"),
    (dict(protocol="lab", container_radius=0.3), "--container-radius"),
    (dict(protocol="lab", duration=0.0, lift_duration=0.0), "without a test"),
    (dict(protocol="bench"), "--protocol must be one of paper, lab, excitation"),
    (dict(wall_mu=0.0), r"--wall-mu does not apply with --protocol paper \(only with --protocol lab\)"),
])
def test_lab_options_are_refused_where_they_do_not_apply(kw, message):
    with pytest.raises(RodwarpError, match=message):
        ProtocolParams(**kw).validate()
