"""``rodwarp phantom`` -> ``rodwarp segment`` -> ``rodwarp analyze`` from the command line."""

import json

import numpy as np
import pytest
import tifffile
from typer.testing import CliRunner

from rodwarp.cli import app
from rodwarp.rodset import load as load_rods

runner = CliRunner()


def _lines(res):
    return [ln for ln in res.output.strip().splitlines() if ln.strip() and "CUDA" not in ln]


def test_phantom_segment_analyze_chain(tmp_path):
    tif = tmp_path / "ct" / "stack.tif"
    res = runner.invoke(app, ["phantom", "random", "--shape", "120", "120", "120", "--n-rods", "12", "--aspect", "12",
                              "--cnr", "8", "--seed", "3", "--out", str(tif)])
    assert res.exit_code == 0, res.output
    truth = load_rods(tmp_path / "ct" / "stack_truth.npz")
    assert truth.units == "voxel" and truth.n_rods == 12
    meta = json.loads((tmp_path / "ct" / "stack_truth.json").read_text())
    assert meta["seed"] == 3 or meta.get("params", {}).get("seed") == 3
    assert tifffile.imread(tif).dtype == np.uint16

    out = tmp_path / "seg"
    res = runner.invoke(app, ["segment", str(tif), "--voxel-size", "0.05", "--units", "mm", "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["n_rods"] == 12
    assert s["diameter"] == pytest.approx(0.05 * 6.0, rel=0.05)  # radius 3 voxels
    rods = load_rods(out / "rods.npz")
    assert rods.units == "mm" and rods.n_rods == 12
    # physical coordinates: voxel (x = column, y = row, z = slice) times the voxel size
    from rodwarp.ct import match_rods

    m = match_rods(rods.to_units("voxel", voxel_size=0.05e-3), truth)
    assert m.f1 == 1.0 and np.max(m.mean_distance) < 1.0
    header = (out / "rods.csv").read_text().splitlines()[0]
    assert header == "rod,x,y,z,radius"
    assert (out / "contacts.csv").read_text().splitlines()[0] == "rod_i,rod_j,x,y,z,gap"
    assert (out / "qa_slices.png").stat().st_size > 10_000 and (out / "qa_projection.png").stat().st_size > 10_000

    res = runner.invoke(app, ["analyze", str(out), "--quiet", "--no-figures", "--keep-outside"])
    assert res.exit_code == 0, res.output
    a = json.loads((out / "analysis" / "summary.json").read_text())
    assert a["contact_source"] == "input" and a["units"] == "mm"


@pytest.mark.parametrize("make, args, fragment", [
    ("2d", [], "2-D"),
    ("constant", [], "constant"),
    ("missing", [], "does not exist"),
    ("noise", [], "no rods"),
    ("ok", ["--voxel-size", "-1"], "voxel-size"),
    ("ok", ["--units", "furlong"], "units"),
])
def test_segment_bad_input_one_line(make, args, fragment, tmp_path):
    p = tmp_path / "x.tif"
    rng = np.random.default_rng(0)
    if make == "2d":
        tifffile.imwrite(p, rng.integers(0, 60000, (32, 32), dtype=np.uint16))
    elif make == "constant":
        tifffile.imwrite(p, np.full((16, 32, 32), 1000, np.uint16))
    elif make == "noise":
        tifffile.imwrite(p, rng.normal(20000, 500, (48, 48, 48)).astype(np.uint16))
    elif make == "ok":
        tifffile.imwrite(p, rng.integers(0, 60000, (16, 32, 32), dtype=np.uint16))
    if make == "missing":
        p = tmp_path / "nope.tif"
    a = ["segment", str(p), *(["--voxel-size", "0.1"] if "--voxel-size" not in args else []), *args,
         "--out", str(tmp_path / "o"), "--quiet"]
    res = runner.invoke(app, a)
    assert res.exit_code == 2, res.output
    lines = _lines(res)
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    assert fragment.lower() in lines[0].lower()
