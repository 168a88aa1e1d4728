"""The scripts in examples/ run as a user runs them, and their printed numbers hold.

Each script runs in its own process (``sys.executable examples/<name>.py``) from the
repository root; the test reads what it printed and checks it against the analytic or true
value with a stated tolerance, so a script that runs but computes the wrong thing fails.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from typer.testing import CliRunner

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
NUM = r"([-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)"


def run_example(name: str, timeout: float = 300.0) -> str:
    r = subprocess.run([sys.executable, str(EXAMPLES / name)], cwd=ROOT, capture_output=True, text=True,
                       timeout=timeout)
    assert r.returncode == 0, f"{name} exited {r.returncode}:\n{r.stdout}\n{r.stderr}"
    return r.stdout


def grab(pattern: str, text: str) -> list[float]:
    m = re.search(pattern, text)
    assert m, f"{pattern!r} not in the output:\n{text}"
    return [float(g) for g in m.groups()]


def test_cantilever_tip_sag_within_2_percent_of_q_L4_over_8EI():
    out = run_example("cantilever.py")
    sag, exact, err = grab(rf"tip sag {NUM} mm, analytic q L\^4/\(8 E I\) {NUM} mm, relative error {NUM}", out)
    assert abs(exact - 49.05) < 0.01  # rho A g L^4 / (8 E I) for the script's rod, in mm
    assert abs(err - (sag - exact) / exact) < 1e-3
    assert abs(err) < 0.02


def test_incline_rolls_at_two_thirds_g_sin_theta():
    out = run_example("incline.py")
    for model in ("elastic", "rigid"):
        a, exact, err, t, wr, v = grab(
            rf"{model}: a = {NUM} m/s\^2, analytic \(2/3\) g sin\(theta\) = {NUM} m/s\^2, relative error {NUM}; "
            rf"at t = {NUM} s omega r = {NUM} m/s, v = {NUM} m/s", out)
        assert abs(exact - 2 / 3 * 9.81 * 0.5) < 1e-4
        assert abs(err) < 0.02 and abs(a - exact) / exact < 0.02
        assert abs(t - 0.5) < 1e-6
        assert abs(wr - v) / v < 1e-3  # rolling without slip: omega r = v
        assert abs(v - exact * t) / (exact * t) < 0.02  # started at rest


def test_analyze_centerlines_prints_the_fields_rodwarp_analyze_writes(tmp_path):
    out = run_example("analyze_centerlines.py")
    n, l, d, alpha = grab(rf"(\d+) rods, l = {NUM} m, d = {NUM} m, aspect ratio {NUM}", out)
    assert (n, round(l, 4), round(d, 4), round(alpha, 1)) == (60, 0.1, 0.002, 50.0)
    R, expect_R = grab(rf"ball radius R = {NUM} m \(sqrt\(d l\) = {NUM} m\)", out)
    assert abs(R - expect_R) < 1e-5
    printed = {name: grab(rf"mean {name} = {NUM}\n", out)[0] for name in ("phi", "S", "c", "e", "n", "n_ends")}
    printed["cv_e"] = grab(rf"cv_e = {NUM}", out)[0]
    # the command line, an independent path through the loader and the options, gives the same
    from rodwarp.cli import app

    res = CliRunner().invoke(app, ["analyze", str(EXAMPLES / "centerlines.csv"), "--diameter", "0.002", "--units", "m",
                                   "--out", str(tmp_path / "a"), "--no-figures", "--quiet"])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    for name, value in printed.items():
        key = name if name == "cv_e" else "mean_" + name
        assert abs(value - summary[key]) <= 1e-5 * abs(summary[key]), (name, value, summary[key])
    assert 0.005 < printed["phi"] < 0.05 and 0 < printed["S"] <= 1 and printed["e"] > 0


def test_check_fields_agrees_with_the_numpy_oracle_to_round_off():
    out = run_example("check_fields.py")
    (n_vox, n_rods) = grab(r"(\d+) voxels of (\d+) rods on cpu", out)
    assert (n_vox, n_rods) == (200, 60)
    for name, tol in (("phi", 1e-15), ("S", 1e-9), ("n", 0.0), ("e", 1e-12)):
        diff, mean = grab(rf"{name}: largest \|warp - numpy\| = {NUM} \(mean {NUM}\)", out)
        assert diff <= tol, f"{name} differs from the oracle by {diff}"
        assert mean > 0  # the voxels hold rods: the comparison is not of empty balls

def test_ct_roundtrip_finds_the_true_rods_and_contacts():
    out = run_example("ct_roundtrip.py")
    found, true, f1 = grab(rf"rods: (\d+) found, (\d+) true, rod F1 {NUM}", out)
    assert true == 12 and found == true and f1 >= 0.95
    found_c, true_c, precision, recall = grab(rf"contacts: (\d+) found, (\d+) true, precision {NUM}, recall {NUM}", out)
    assert true_c >= 1 and found_c >= 1 and precision >= 0.75 and recall >= 0.75
    dia, dia_true, dist = grab(rf"diameter: {NUM} voxels found, {NUM} true; mean centreline distance {NUM} voxels", out)
    assert dia_true == 6.0 and abs(dia - dia_true) / dia_true < 0.05
    assert dist < 0.5


def test_pour_cylinder_keeps_every_rod_in_the_tube_and_the_short_rods_spread_when_it_is_lifted():
    out = run_example("pour_cylinder.py")
    h0, r0, tube = grab(rf"in the tube: height {NUM} cm, radius {NUM} cm \(tube {NUM} cm\), every rod inside: True", out)
    h1, r1 = grab(rf"after the lift: height {NUM} cm, radius {NUM} cm", out)
    assert r0 <= tube + 0.01 and 0 < h0 < 20  # poured, settled, inside the tube
    assert h1 < 0.5 * h0 and r1 > 2 * tube  # alpha 20 does not stand: it spreads


def test_custom_stage_runs_the_lift_between_entangling_and_the_test():
    out = run_example("custom_stage.py")
    assert "stages: entangle -> lift -> stability" in out
    (t0,) = grab(rf"test started at t = {NUM} s", out)
    assert abs(t0 - 0.4) < 1e-9  # after 0.2 s of entangling and 0.2 s of the lift


def test_make_centerlines_remakes_the_shipped_csv_byte_for_byte(tmp_path):
    # run a copy beside an empty folder, so the shipped examples/centerlines.csv is not rewritten
    import shutil

    shutil.copy(EXAMPLES / "make_centerlines.py", tmp_path)
    r = subprocess.run([sys.executable, str(tmp_path / "make_centerlines.py")], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "60 rods ->" in r.stdout
    assert (tmp_path / "centerlines.csv").read_bytes() == (EXAMPLES / "centerlines.csv").read_bytes()
