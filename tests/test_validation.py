"""Every option of every command is checked before any work: one line, what is wrong and how
to fix it, exit code 2, and nothing written (issue 15)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from rodwarp.cli import app, main
from rodwarp.rodset import RodSet

runner = CliRunner()

SHORT = ["--alpha", "20", "--n-rods", "12", "--entangle-duration", "0.02", "--duration", "0.02", "--save-every",
         "0.01", "--device", "cpu", "--quiet"]


def _lines(res):
    return [ln for ln in res.output.strip().splitlines() if ln.strip() and "CUDA" not in ln]


def refused(args, fragment, tmp_path=None, out_name="o"):
    """Invoke the CLI; it must exit 2 with one 'error:' line holding ``fragment``."""
    res = runner.invoke(app, args)
    lines = _lines(res)
    assert res.exit_code == 2, res.output
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    assert fragment in lines[0], lines[0]
    assert "Traceback" not in res.output
    return lines[0]


# ------------------------------------------------------------------------------ non-finite values

SIMULATE_NUMERIC = ["alpha", "freq", "amplitude", "gravity", "duration", "entangle-duration", "entangle-freq",
                    "entangle-amplitude", "static-load", "length", "mu", "young", "density", "dt", "save-every",
                    "checkpoint-every"]


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
@pytest.mark.parametrize("option", SIMULATE_NUMERIC)
def test_simulate_non_finite_option_is_named(option, value, tmp_path):
    out = tmp_path / "o"
    args = ["simulate", *SHORT, f"--{option}", value, "--out", str(out)]
    refused(args, f"--{option}")
    assert not out.exists()  # refused before any work


@pytest.mark.parametrize("box", ["nan,1,2.5", "1,inf,2.5", "1,1,-inf", "1,1,0"])
def test_simulate_box_must_be_finite_and_positive(box, tmp_path):
    refused(["simulate", *SHORT, "--box", box, "--out", str(tmp_path / "o")], "--box")


@pytest.mark.parametrize("args, fragment", [
    (["--vertices", "1"], "--vertices must be >= 2"),
    (["--iterations", "0"], "--iterations must be >= 1"),
    (["--seed", "-1"], "--seed must be >= 0"),
    (["--n-rods", "0"], "--n-rods must be >= 1"),
    (["--device", "tpu"], "unknown device"),
    (["--entangle"], "--entangle only applies with --initial"),
    (["--resume", "--overwrite"], "contradict"),
])
def test_simulate_out_of_range_or_inconsistent(args, fragment, tmp_path):
    refused(["simulate", *SHORT, *args, "--out", str(tmp_path / "o")], fragment)


# ------------------------------------------------------------------------------ zero-step runs

@pytest.mark.parametrize("args, fragment", [
    (["--dt", "0.5"], "not a single full step fits"),  # dt above every (0.02 s) duration
    (["--dt", "10"], "--dt must be > 0 s and <= 1 s"),  # beyond the option's range
    (["--dt", "0.03"], "--dt 0.03 s is longer than the"),  # above the 0.02 s stages
    (["--duration", "0"], "--duration 0 leaves the stability test without a step"),
    (["--save-every", "0.5"], "longer than the stability test"),
    (["--freq", "1000", "--amplitude", "1e-6", "--duration", "1e5"], "steps"),
])
def test_zero_step_and_inconsistent_durations_are_refused(args, fragment, tmp_path):
    out = tmp_path / "o"
    refused(["simulate", *SHORT, *args, "--out", str(out)], fragment)
    assert not (out / "final.npz").exists() and not (out / "metrics.csv").exists()


# ------------------------------------------------------------------------------ oversized requests

@pytest.mark.parametrize("args, fragment", [
    (["--n-rods", "10000000"], "of memory"),
    (["--alpha", "1e4", "--n-rods", "100000000"], "of memory"),
    (["--n-rods", "5000"], "phi * alpha"),  # 5000 rods of alpha 20 cannot be packed into the box
    (["--box", "0.3,0.3,0.3"], "too small to hold one rod"),
])
def test_simulate_oversized_requests_give_the_estimate(args, fragment, tmp_path):
    line = refused(["simulate", *SHORT, *args, "--out", str(tmp_path / "o")], fragment)
    if "memory" in fragment:
        assert "needs about" in line and "is available" in line


def test_default_alpha_1e4_is_refused_by_its_memory_estimate(tmp_path):
    # alpha at the top of its range: round(5.4 alpha) = 54000 rods of the default 10 vertices fit;
    # with 10000 vertices each they need about 2 TB
    line = refused(["simulate", "--alpha", "1e4", "--vertices", "10000", "--out", str(tmp_path / "o")],
                   "needs about")
    assert "54000 rods x 10000 vertices" in line


def test_phantom_volume_too_large_is_refused_with_its_estimate(tmp_path):
    line = refused(["phantom", "random", "--shape", "2000", "2000", "2000", "--out", str(tmp_path / "x.tif")],
                   "needs about")
    assert "8e+09 voxels" in line and not (tmp_path / "x.tif").exists()


def test_disk_too_small_for_the_frames_is_refused(tmp_path, monkeypatch):
    import shutil
    from collections import namedtuple

    du = namedtuple("du", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: du(10**6, 10**6 - 1000, 1000))
    out = tmp_path / "o"
    line = refused(["simulate", *SHORT, "--out", str(out)], "on disk")
    assert "is free at" in line and str(tmp_path) in line


# ------------------------------------------------------------------------------ analyze, phantom, segment

@pytest.fixture
def rods_file(tmp_path):
    s = np.linspace(-0.5, 0.5, 10)
    polys = [np.stack([s, 0 * s + y, 0 * s + 0.2 + 0.1 * k], 1) for k, y in enumerate((0.0, 0.3, 0.6))]
    p = tmp_path / "rods.npz"
    RodSet.from_polylines(polys, radii=0.01).save(p)
    return p


@pytest.mark.parametrize("option", ["radius", "spacing", "diameter", "length", "contact-tolerance"])
@pytest.mark.parametrize("value", ["nan", "inf"])
def test_analyze_non_finite_option_is_named(option, value, rods_file, tmp_path):
    refused(["analyze", str(rods_file), f"--{option}", value, "--out", str(tmp_path / "a"), "--quiet"], f"--{option}")


def test_analyze_bins_and_huge_grid(rods_file, tmp_path):
    refused(["analyze", str(rods_file), "--bins", "1", "--out", str(tmp_path / "a")], "--bins")
    refused(["analyze", str(rods_file), "--radius", "0.01", "--spacing", "1e-5", "--out", str(tmp_path / "a")],
            "it must be 0.01 to 2 R")
    refused(["analyze", str(rods_file), "--radius", "1e-9", "--out", str(tmp_path / "a")],
            "--radius 1e-09 m is below half the rods' diameter")
    assert not (tmp_path / "a").exists()


@pytest.mark.parametrize("option, value", [("voxel-size", "nan"), ("blur", "inf"), ("cnr", "nan"), ("ring", "-inf"),
                                           ("cupping", "nan"), ("streaks", "inf"), ("radius", "nan"),
                                           ("aspect", "inf"), ("touching", "nan"), ("touching", "1.5")])
def test_phantom_options_are_checked(option, value, tmp_path):
    refused(["phantom", "random", "--shape", "32", "32", "32", f"--{option}", value, "--out",
             str(tmp_path / "p.tif")], f"--{option}")


def test_phantom_output_must_be_a_tiff_in_a_writable_place(tmp_path):
    small = ["phantom", "random", "--shape", "32", "32", "32", "--radius", "2", "--aspect", "4"]
    refused([*small, "--out", str(tmp_path / "p.png")], ".tif")
    (tmp_path / "file").write_text("x")
    refused([*small, "--out", str(tmp_path / "file" / "p.tif")], "is a file")


@pytest.mark.parametrize("args, fragment", [
    (["--voxel-size", "nan"], "--voxel-size"),
    (["--voxel-size", "1", "--diameter", "inf"], "--diameter"),
    (["--voxel-size", "1", "--contact-tolerance", "nan"], "--contact-tolerance"),
    (["--voxel-size", "1", "--chunk", "2"], "--chunk"),
    (["--voxel-size", "1", "--units", "furlong"], "--units"),
])
def test_segment_options_are_checked_before_reading_the_stack(args, fragment, tmp_path):
    stack = tmp_path / "s.tif"
    stack.write_bytes(b"not read before the options are checked")
    refused(["segment", str(stack), *args, "--out", str(tmp_path / "seg")], fragment)


def test_segment_out_is_a_file_fails_before_segmenting(tmp_path):
    stack = tmp_path / "s.tif"
    stack.write_bytes(b"never read")
    (tmp_path / "seg").write_text("a file")
    refused(["segment", str(stack), "--voxel-size", "1", "--out", str(tmp_path / "seg")], "is a file")


# ------------------------------------------------------------------------------ input rod sets

def _two_rods(z, gap_over_d, d=0.01, box=None):
    s = np.linspace(-0.5, 0.5, 10)
    a = np.stack([s, 0 * s, 0 * s + z], 1)
    b = np.stack([0 * s, s, 0 * s + z + d * (1 + gap_over_d)], 1)
    return RodSet.from_polylines([a, b], radii=d / 2, box=box)


def test_overlapping_input_rods_are_named(tmp_path):
    p = tmp_path / "overlap.npz"
    rods = _two_rods(0.2, -0.9)  # centrelines 0.1 d apart: overlap 0.9 d
    extra = RodSet.from_polylines([np.stack([np.linspace(-0.5, 0.5, 10), np.full(10, 0.4), np.full(10, 0.2)], 1)],
                                  radii=0.005)
    RodSet.from_polylines([rods.rod(0), extra.rod(0), rods.rod(1)], radii=0.005).save(p)
    line = refused(["simulate", "--initial", str(p), "--duration", "0.02", "--save-every", "0.01", "--out",
                    str(tmp_path / "o"), "--device", "cpu", "--quiet"], "rods 0 and 2 overlap by 0.9 d")
    assert "separate them" in line


@pytest.mark.parametrize("args, fragment", [
    (["--n-rods", "5"], "--n-rods does not apply with --initial"),
    (["--box", "2,2,2"], "--box does not apply"),
    (["--alpha", "50"], "--alpha 50 contradicts the input rods"),
])
def test_options_the_input_decides_are_refused(args, fragment, tmp_path):
    p = tmp_path / "in.npz"
    _two_rods(0.2, 0.5).save(p)
    refused(["simulate", "--initial", str(p), *args, "--duration", "0.02", "--save-every", "0.01", "--out",
             str(tmp_path / "o"), "--device", "cpu", "--quiet"], fragment)


def test_input_rods_on_the_box_floor_and_alpha_from_the_input(tmp_path):
    # two alpha-50 rods lying on z = 0 (centrelines at 0: sunk half a diameter into the box's
    # floor); the floor goes under their lowest point, alpha/d/l come from the rods
    d = 0.02
    p = tmp_path / "flat.npz"
    s = np.linspace(-0.5, 0.5, 10)
    RodSet.from_polylines([np.stack([s, 0 * s, 0 * s], 1), np.stack([s, 0 * s + 0.3, 0 * s], 1)], radii=d / 2,
                          box=np.array([[-1.0, -1.0, 0.0], [1.0, 1.0, 1.0]])).save(p)
    out = tmp_path / "o"
    res = runner.invoke(app, ["simulate", "--initial", str(p), "--duration", "0.02", "--save-every", "0.01", "--out",
                              str(out), "--device", "cpu", "--quiet"])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["alpha"] == pytest.approx(50.0) and s["diameter"] == pytest.approx(d) and s["length"] == pytest.approx(1.0)
    assert s["parameters"]["alpha"] == pytest.approx(50.0)
    assert s["test_start"]["height"] == pytest.approx(d / 2, rel=0.05)  # centroid above the floor under the rods
    assert "alpha=50 " in res.output


# ------------------------------------------------------------------------------ sweep

@pytest.mark.parametrize("args, fragment", [
    (["--alpha", "0"], "--alpha must be > 1"),
    (["--alpha", "20,0"], "--alpha must be > 1 and <= 10000, got 0"),
    (["--alpha", "20", "--freq", "1,1000"], "invalid points: 1 of 2"),  # in range, but a/g 7.9e4 at 1000 Hz
    (["--freq", "nan"], "--freq values must be finite"),
    (["--gravity", "inf"], "--gravity values must be finite"),
    (["--static-load", "-1"], "--static-load must be >= 0"),
    (["--device", "bogus"], "unknown device"),
    (["--duration", "nan"], "--duration"),
    (["--entangle-duration", "inf"], "--entangle-duration"),
    (["--amplitude", "nan"], "--amplitude"),
    (["--duration", "0.05"], "--save-every 0.1 s is longer than the stability test"),
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--workers", "0"], "--workers must be >= 1"),
    (["--scheduler", "garbage"], "not a Dask scheduler address"),
    (["--scheduler", "tcp://127.0.0.1:1"], "does not answer"),
])
def test_sweep_refused_before_any_cluster_starts(args, fragment, tmp_path):
    out = tmp_path / "sw"
    refused(["sweep", "--freq", "1", *args, "--out", str(out), "--quiet"] if "--freq" not in args else
            ["sweep", *args, "--out", str(out), "--quiet"], fragment)
    assert not (out / "sweep.json").exists() and not (out / "results.csv").exists()


# ------------------------------------------------------------------------------ the command itself

def test_version_and_bare_command(capsys):
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("rodwarp ") and "warp" in out
    assert main([]) == 0
    out = capsys.readouterr()
    assert "Usage: rodwarp" in out.out and "simulate" in out.out and "error" not in out.err


@pytest.mark.parametrize("command", ["simulate", "analyze", "phantom", "segment", "sweep", "phase-diagram", "version"])
def test_help_has_an_example(command):
    res = runner.invoke(app, [command, "--help"])
    assert res.exit_code == 0
    assert "Example: rodwarp " + command in " ".join(res.output.split())
