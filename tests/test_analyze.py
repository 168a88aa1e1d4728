"""``rodwarp analyze``: every input kind, every output, one-line errors."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from rodwarp.analysis import Fields
from rodwarp.cli import app
from rodwarp.experiments import random_packing
from rodwarp.rodset import load as load_rods

runner = CliRunner()
PAPER = Path(__file__).resolve().parents[2] / "shared" / "data" / "paper-fields"
KEYS = ("mean_phi", "mean_S", "mean_c", "mean_e", "cv_e", "e_lb", "outlier_fraction", "n_tangles",
        "largest_tangle_extent", "percolates")


def _lines(res):
    return [ln for ln in res.output.strip().splitlines() if ln.strip() and "CUDA" not in ln]


@pytest.fixture(scope="module")
def packing():
    return random_packing(100, 1.0, 1 / 40, (1.0, 1.0, 1.5), seed=3)


def test_simulate_output_directory(tmp_path):
    run = tmp_path / "run"
    res = runner.invoke(app, ["simulate", "--alpha", "20", "--n-rods", "40", "--entangle-duration", "0.05",
                              "--duration", "0.05", "--save-every", "0.05", "--out", str(run), "--quiet",
                              "--device", "cpu"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["analyze", str(run), "--quiet"])
    assert res.exit_code == 0, res.output
    out = run / "analysis"
    s = json.loads((out / "summary.json").read_text())
    for k in KEYS:
        assert k in s
    assert s["contact_source"] == "input"  # the simulation's own contacts
    f = Fields.load(out / "fields.zarr")
    rods = load_rods(run / "final.npz")
    d, l = 2 * rods.radii.mean(), rods.rod_lengths().mean()
    assert f.radius == pytest.approx(math.sqrt(d * l)) and f.spacing == pytest.approx(f.radius / 2)
    assert f.units == "m"
    for name in ("histograms.png", "slices.png", "zprofiles.png", "tangles.png"):
        assert (out / name).stat().st_size > 10_000
    v = f.valid
    assert s["mean_e"] == pytest.approx(float(np.mean(f.e[v])))
    assert s["cv_e"] == pytest.approx(float(np.std(f.e[v]) / np.mean(f.e[v])))


def test_fields_zarr_layout(packing, tmp_path):
    import zarr

    src = tmp_path / "rods.npz"
    packing.save(src)
    out = tmp_path / "an"
    res = runner.invoke(app, ["analyze", str(src), "--out", str(out), "--quiet", "--no-figures"])
    assert res.exit_code == 0, res.output
    g = zarr.open_group(str(out / "fields.zarr"), mode="r")
    for name in ("phi", "S", "c", "e", "n", "x", "y", "z"):
        assert name in g
    assert g["e"].shape == (g["z"].shape[0], g["y"].shape[0], g["x"].shape[0])
    assert g.attrs["axis_order"] == "z,y,x" and g.attrs["units"] == "m"
    assert g.attrs["radius"] > 0 and g.attrs["spacing"] == pytest.approx(g.attrs["radius"] / 2)
    s = json.loads((out / "summary.json").read_text())
    assert s["contact_source"].startswith("detected")
    assert not list(out.glob("*.png"))


def test_csv_input_needs_diameter(packing, tmp_path):
    csv = tmp_path / "rods.csv"
    lines = ["rod,x,y,z"]
    for i in range(packing.n_rods):
        for p in packing.rod(i):
            lines.append(f"{i},{float(p[0])!r},{float(p[1])!r},{float(p[2])!r}")
    csv.write_text("\n".join(lines) + "\n")
    res = runner.invoke(app, ["analyze", str(csv), "--quiet"])
    assert res.exit_code == 2 and len(_lines(res)) == 1 and "--diameter" in _lines(res)[0]
    out = tmp_path / "a"
    res = runner.invoke(app, ["analyze", str(csv), "--diameter", str(1 / 40), "--out", str(out), "--quiet",
                              "--no-figures"])
    assert res.exit_code == 0, res.output
    # the same rods from an npz without a box give the same fields (both on the bounding box)
    nobox = packing.copy()
    nobox.box = None
    npz = tmp_path / "r.npz"
    nobox.save(npz)
    out2 = tmp_path / "b"
    res = runner.invoke(app, ["analyze", str(npz), "--out", str(out2), "--quiet", "--no-figures"])
    assert res.exit_code == 0, res.output
    a = Fields.load(out / "fields.zarr")
    b = Fields.load(out2 / "fields.zarr")
    assert a.shape == b.shape and np.nanmean(a.e) > 0
    for k in ("phi", "S", "c", "e", "n"):
        np.testing.assert_allclose(getattr(a, k), getattr(b, k), rtol=1e-12, atol=1e-12)


@pytest.mark.skipif(not PAPER.exists(), reason="paper fields not present")
def test_precomputed_paper_fields(tmp_path):
    src = PAPER / "alpha100_epsilon00.npz"
    out = tmp_path / "p"
    res = runner.invoke(app, ["analyze", str(src), "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    with np.load(src) as z:
        e, n = z["e"].astype(float), z["n"]
    v = n > 0
    assert s["mean_e"] == pytest.approx(float(e[v].mean()), rel=1e-9)
    q1, q3 = np.percentile(e[v], [25, 75])
    assert s["e_lb"] == pytest.approx(q3 + 1.5 * (q3 - q1), rel=1e-9)
    assert s["units"] == "voxel" and s["radius"] == 64.0
    assert s["outlier_fraction"] == pytest.approx(float((e[v] > s["e_lb"]).mean()))


def test_connectivity_and_outlier_options(tmp_path):
    if not PAPER.exists():
        pytest.skip("paper fields not present")
    src = PAPER / "alpha38_epsilon00.npz"
    res26 = runner.invoke(app, ["analyze", str(src), "--out", str(tmp_path / "a"), "--quiet", "--no-figures"])
    res6 = runner.invoke(app, ["analyze", str(src), "--out", str(tmp_path / "b"), "--quiet", "--no-figures",
                               "--connectivity", "6", "--outlier", "q1"])
    assert res26.exit_code == 0 and res6.exit_code == 0
    a = json.loads((tmp_path / "a" / "summary.json").read_text())
    b = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert b["e_lb"] < a["e_lb"]  # Q1 + 1.5 IQR < Q3 + 1.5 IQR
    assert b["outlier_fraction"] > a["outlier_fraction"]


@pytest.mark.parametrize("args, fragment", [
    (["/nonexistent/rods.npz"], "does not exist"),
    (["{tmp}/rods.npz", "--radius", "-1"], "--radius must be > 0"),
    (["{tmp}/rods.npz", "--connectivity", "8"], "connectivity"),
    (["{tmp}/rods.npz", "--outlier", "median"], "--outlier"),
    (["{tmp}/rods.npz", "--radius", "50"], "no ball"),
    (["{tmp}/rods.npz", "--device", "tpu"], "unknown device"),
    (["{tmp}/nan.csv", "--diameter", "0.01"], "not finite"),
    (["{tmp}/empty_dir"], "holds none"),
    (["{tmp}/rods.npz", "--units", "furlong"], "unit"),
])
def test_bad_input_one_line(args, fragment, packing, tmp_path):
    packing.save(tmp_path / "rods.npz")
    (tmp_path / "nan.csv").write_text("rod,x,y,z\n0,0,0,0\n0,nan,1,1\n")
    (tmp_path / "empty_dir").mkdir()
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    res = runner.invoke(app, ["analyze", *args, "--out", str(tmp_path / "o"), "--quiet"])
    assert res.exit_code == 2, res.output
    lines = _lines(res)
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    assert fragment in lines[0]
