"""Units everywhere a length enters (issue 29, class 3): phantom -> segment keeps the rods' units,
simulate/analyze/phantom read a CSV in --units, and implausible scales are refused in one line."""

import json

import numpy as np
import pytest

from rodwarp.cli import main
from rodwarp.rodset import RodSet, load
from rodwarp.rodset._formats import save_csv


def _run(args, capsys):
    """Exit code and the stderr lines (warp's CUDA notice left out) of ``rodwarp ARGS``."""
    rc = main([str(a) for a in args])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip() and "CUDA" not in ln]
    return rc, err


def _refused(args, capsys, *fragments):
    rc, err = _run(args, capsys)
    assert rc == 2, err
    assert len(err) == 1 and err[0].startswith("error: "), err
    for f in fragments:
        assert f in err[0], err[0]
    return err[0]


def _phantom_rods() -> RodSet:
    """Six straight rods, 0.1 m long and 0.01 m thick, inside a 0.16 m cube (metres)."""
    pts, off = [], [0]
    d = np.array([0.0, 0.8, 0.6]) * 0.05
    for i in range(6):
        c = np.array([0.03 + 0.018 * i, 0.08, 0.08])
        pts += [c - d, c + d]
        off.append(len(pts))
    return RodSet(np.array(pts), np.array(off), np.full(6, 0.005), units="m")


def _sim_rods() -> RodSet:
    """16 separated rods 20 mm long and 1 mm thick, in metres (a 4 x 4 grid, random directions)."""
    rng = np.random.default_rng(1)
    pts, off = [], [0]
    for i in range(4):
        for j in range(4):
            c = np.array([0.01 + 0.02 * i, 0.01 + 0.02 * j, 0.02 + 0.01 * rng.random()])
            d = rng.normal(size=3)
            d[2] *= 0.3
            d *= 0.01 / np.linalg.norm(d)
            pts += [c - d, c + d]
            off.append(len(pts))
    return RodSet(np.array(pts), np.array(off), np.full(16, 0.0005), units="m")


# ---------------------------------------------------------------------------------- phantom/segment

@pytest.mark.parametrize("unit, voxel", [("m", 0.0025), ("mm", 2.5)])
def test_phantom_then_segment_without_voxel_size_keeps_the_rods_units(unit, voxel, tmp_path, capsys):
    rods = _phantom_rods().to_units(unit)
    rods.save(tmp_path / "rods.npz")
    tif = tmp_path / "p.tif"
    rc, err = _run(["phantom", tmp_path / "rods.npz", "--voxel-size", voxel, "--shape", 64, 64, 64,
                    "--cnr", 8, "--out", tif], capsys)
    assert rc == 0, err
    meta = json.loads((tmp_path / "p_truth.json").read_text())
    assert meta["units"] == unit and meta["voxel_size"] == pytest.approx(voxel)
    assert meta["voxel_size_zyx_m"] == pytest.approx([0.0025] * 3)  # was 1 um whatever the rods

    from rodwarp.ct import read_voxel_size, read_voxel_unit

    sizes, _ = read_voxel_size(tif)
    assert sizes == pytest.approx((0.0025,) * 3) and read_voxel_unit(tif) == unit

    out = tmp_path / "seg"
    rc, err = _run(["segment", tif, "--out", out, "--quiet", "--no-figures"], capsys)
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["units"] == unit and s["n_rods"] == 6
    true_d = 0.01 if unit == "m" else 10.0
    assert s["diameter"] == pytest.approx(true_d, rel=0.05)
    assert s["voxel_size_zyx"] == pytest.approx([voxel] * 3)
    seg = load(out / "rods.npz")
    assert seg.units == unit and 2 * np.median(seg.radii) == pytest.approx(true_d, rel=0.05)


@pytest.mark.parametrize("args, fragments", [
    # 0.01 m rods at the default 1 m voxel: 0.01 voxel thick, pure noise
    (["{m}", "--shape", 64, 64, 64], ("0.01 voxels thick", "--voxel-size 0.0025")),
    (["random", "--radius", 0.1, "--shape", 32, 32, 32], ("--radius must be >= 0.5 voxels", "got 0.1")),
    (["random", "--ring", 1e9, "--shape", 32, 32, 32], ("--ring must be >= 0 and <= 1", "1e+09")),
    (["random", "--streaks", 5, "--shape", 32, 32, 32], ("--streaks must be >= 0 and <= 1",)),
    (["{m}", "--voxel-size", 0.0025, "--shape", 32, 32, 32], ("do not fit the volume", "enlarge --shape to 47 51 51",
                                                                "--voxel-size to 0.00397 m")),
])
def test_phantom_scale_and_artefact_refusals(args, fragments, tmp_path, capsys):
    _phantom_rods().save(tmp_path / "m.npz")
    args = [str(tmp_path / "m.npz") if a == "{m}" else a for a in args]
    _refused(["phantom", *args, "--out", tmp_path / "p.tif"], capsys, *fragments)
    assert not (tmp_path / "p.tif").exists()


def test_phantom_csv_in_mm_with_units(tmp_path, capsys):
    save_csv(_phantom_rods().to_units("mm"), tmp_path / "r.csv")
    rc, err = _run(["phantom", tmp_path / "r.csv", "--units", "mm", "--voxel-size", 2.5, "--shape", 64, 64, 64,
                    "--out", tmp_path / "p.tif"], capsys)
    assert rc == 0, err
    meta = json.loads((tmp_path / "p_truth.json").read_text())
    assert meta["units"] == "mm" and meta["voxel_size"] == 2.5 and meta["voxel_size_zyx_m"] == pytest.approx([0.0025] * 3)
    # an npz is converted to --units: the voxel size is then in them
    _phantom_rods().save(tmp_path / "m.npz")
    rc, err = _run(["phantom", tmp_path / "m.npz", "--units", "mm", "--voxel-size", 2.5, "--shape", 64, 64, 64,
                    "--out", tmp_path / "q.tif"], capsys)
    assert rc == 0, err
    meta = json.loads((tmp_path / "q_truth.json").read_text())
    assert meta["units"] == "mm" and meta["voxel_size_zyx_m"] == pytest.approx([0.0025] * 3)


# ---------------------------------------------------------------------------------- simulate

SIM = ["--duration", 0.02, "--save-every", 0.01, "--device", "cpu", "--quiet", "--amplitude", 0.0005,
       "--entangle-amplitude", 0.001]


def test_simulate_initial_csv_in_mm_runs_in_metres(tmp_path, capsys):
    save_csv(_sim_rods().to_units("mm"), tmp_path / "r.csv")
    rc, err = _run(["simulate", "--initial", tmp_path / "r.csv", "--units", "mm", *SIM, "--out", tmp_path / "run"],
                   capsys)
    assert rc == 0, err
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert s["length"] == pytest.approx(0.02, rel=1e-9) and s["diameter"] == pytest.approx(0.001, rel=1e-9)
    assert s["parameters"]["units"] == "mm"
    assert load(tmp_path / "run" / "initial.npz").units == "m"


def test_simulate_initial_implausible_length_points_at_units(tmp_path, capsys):
    save_csv(_sim_rods().to_units("um"), tmp_path / "r.csv")  # 20000 um rods read as 20000 m
    _refused(["simulate", "--initial", tmp_path / "r.csv", *SIM, "--out", tmp_path / "run"], capsys,
             "2e+04 m long", "--units um")
    assert not (tmp_path / "run").exists()


def test_simulate_units_voxel_and_without_initial_refused(tmp_path, capsys):
    save_csv(_sim_rods(), tmp_path / "r.csv")
    _refused(["simulate", "--initial", tmp_path / "r.csv", "--units", "voxel", *SIM, "--out", tmp_path / "run"],
             capsys, "--units voxel", "simulate runs in metres")
    _refused(["simulate", "--units", "mm", *SIM, "--out", tmp_path / "run"], capsys,
             "--units only applies with --initial")


def test_simulate_diameter_contradicting_the_radii_refused(tmp_path, capsys):
    save_csv(_sim_rods().to_units("mm"), tmp_path / "r.csv")
    _refused(["simulate", "--initial", tmp_path / "r.csv", "--units", "mm", "--diameter", 3, *SIM,
              "--out", tmp_path / "run"], capsys, "--diameter 3 mm", "median diameter 1 mm", "drop --diameter")


# ---------------------------------------------------------------------------------- CSV without radius

def _no_radius_csv(path):
    rods = _sim_rods()
    with open(path, "w") as fh:
        fh.write("rod,x,y,z\n")
        for k in range(rods.n_rods):
            for p in rods.points[rods.offsets[k]:rods.offsets[k + 1]]:
                fh.write(f"{k},{float(p[0])!r},{float(p[1])!r},{float(p[2])!r}\n")


def test_csv_without_radius_is_refused_not_guessed(tmp_path, capsys):
    _no_radius_csv(tmp_path / "r.csv")
    for cmd in (["simulate", "--initial", tmp_path / "r.csv", *SIM, "--out", tmp_path / "run"],
                ["analyze", tmp_path / "r.csv", "--out", tmp_path / "a", "--quiet"]):
        _refused(cmd, capsys, "no radius column", "add a radius column", "--diameter")
    assert not (tmp_path / "run").exists() and not (tmp_path / "a").exists()
    # with --diameter the rods take it
    rc, err = _run(["simulate", "--initial", tmp_path / "r.csv", "--diameter", 0.001, *SIM, "--out", tmp_path / "run"],
                   capsys)
    assert rc == 0, err
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert s["diameter"] == pytest.approx(0.001) and s["parameters"]["initial_diameter"] == 0.001


# ---------------------------------------------------------------------------------- analyze

def test_analyze_diameter_contradicting_the_radii_refused(tmp_path, capsys):
    save_csv(_sim_rods(), tmp_path / "r.csv")  # radii 0.0005 m: diameter 0.001 m
    _refused(["analyze", tmp_path / "r.csv", "--diameter", 0.5, "--out", tmp_path / "a", "--quiet"], capsys,
             "--diameter 0.5 m", "median diameter 0.001 m", "drop --diameter")
    _sim_rods().save(tmp_path / "r.npz")
    _refused(["analyze", tmp_path / "r.npz", "--diameter", 0.0011, "--out", tmp_path / "a", "--quiet"], capsys,
             "--diameter 0.0011 m", "10% off")
    assert not (tmp_path / "a").exists()


def test_analyze_huge_grid_from_wrong_units_points_at_units(tmp_path, capsys):
    save_csv(_sim_rods().to_units("um"), tmp_path / "r.csv")  # read as metres: 20000 m rods
    line = _refused(["analyze", tmp_path / "r.csv", "--spacing", 0.0001, "--out", tmp_path / "a", "--quiet"], capsys,
                    "check the units first", "2e+04 m long and 1000 m thick", "--units um")
    assert line.index("--units um") < line.index("raise --spacing")
