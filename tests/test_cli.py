"""The command line: one-line errors for bad input, and a short end-to-end run."""

import json

import pytest
from typer.testing import CliRunner

from rodwarp.cli import app

runner = CliRunner()


@pytest.mark.parametrize("args, fragment", [
    (["--alpha", "0.5"], "--alpha must be > 1"),
    (["--alpha", "-3"], "--alpha must be > 1"),
    (["--freq", "-1"], "--freq must be >= 0"),
    (["--amplitude", "2.0", "--freq", "1"], "--amplitude 2 m (a stroke of 4 m) does not fit the box"),
    (["--amplitude", "2.0"], "make a/g = 1.58e+04"),
    (["--length", "1e-9"], "--length must be >= 1e-05 m"),
    (["--box", "1,1"], "--box must be three"),
    (["--initial", "/nonexistent/rods.npz"], "not found"),
    (["--device", "tpu"], "unknown device"),
])
def test_bad_parameters_fail_with_one_line(args, fragment, tmp_path):
    res = runner.invoke(app, ["simulate", *args, "--out", str(tmp_path / "o"), "--quiet"])
    assert res.exit_code == 2
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip() and "CUDA" not in ln]
    assert len(lines) == 1 and lines[0].startswith("error:")
    assert fragment in lines[0]
    assert "Traceback" not in res.output


def test_short_simulation_writes_its_outputs(tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["simulate", "--alpha", "20", "--n-rods", "30", "--entangle-duration", "0.05",
                              "--duration", "0.05", "--save-every", "0.025", "--seed", "7", "--out", str(out),
                              "--quiet", "--device", "cpu"])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    for key in ("alpha", "n_rods", "freq", "amplitude", "gravity", "a_over_g", "contacts_per_rod",
                "largest_cluster_fraction", "height_kept", "persistence", "rods_left", "thresholds", "stable_rule",
                "test_start", "stable", "seed", "dt", "steps", "wall_time_s", "versions", "parameters"):
        assert key in summary
    assert summary["n_rods"] == 30 and summary["seed"] == 7
    assert abs(summary["a_over_g"] - 4 * 3.141592653589793**2 * 100 * 0.001 / 0.5) < 1e-9
    assert (out / "metrics.csv").read_text().count("\n") >= 3
    assert (out / "final.npz").exists() and (out / "metrics.png").exists()


@pytest.mark.parametrize("args, fragment", [
    (["simulate", "--alpha", "abc"], "Invalid value for '--alpha'"),
    (["simulate", "--bogus"], "No such option"),
    (["analyze"], "Missing argument"),
    (["phantom", "random", "--shape", "9", "9", "--out", "x.tif"], "--shape"),
])
def test_usage_errors_are_one_line(args, fragment, capsys):
    from rodwarp.cli import main

    assert main(args) == 2
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "CUDA" not in ln]
    assert len(err) == 1 and err[0].startswith("error:") and fragment in err[0]
