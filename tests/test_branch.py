"""One entangled packing, several stability tests: a run whose test starts from another run's
entangled.npz ends bit for bit where a run of its own entangling ends (docs/protocol.md)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rodwarp.rodset import load

ARGS = ["simulate", "--alpha", "20", "--n-rods", "40", "--entangle-duration", "0.3", "--duration", "0.3",
        "--save-every", "0.05", "--checkpoint-every", "0.05", "--seed", "5", "--device", "cpu", "--quiet"]


def run(out: Path, *extra):
    return subprocess.run([sys.executable, "-m", "rodwarp.cli", *ARGS, "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("branch")
    for name, extra in (("own", ("--freq", "20", "--amplitude", "0.002")), ("donor", ("--freq", "10"))):
        r = run(base / name, *extra)
        assert r.returncode == 0, r.stderr
    r = run(base / "branch", "--freq", "20", "--amplitude", "0.002", "--entangled-from", str(base / "donor"))
    assert r.returncode == 0, r.stderr
    return base


def test_branched_test_equals_a_run_of_its_own_entangling(runs):
    own, branch, donor = runs / "own", runs / "branch", runs / "donor"
    a, b = load(own / "final.npz"), load(branch / "final.npz")
    assert np.array_equal(a.points, b.points) and np.array_equal(a.velocities, b.velocities)
    # the whole time series, the entangling samples included
    assert (own / "metrics.csv").read_text() == (branch / "metrics.csv").read_text()
    import zarr

    ga, gb = zarr.open_group(str(own / "trajectory.zarr"), mode="r"), zarr.open_group(str(branch / "trajectory.zarr"),
                                                                                      mode="r")
    assert ga.attrs["n_frames"] == gb.attrs["n_frames"]
    assert np.array_equal(ga["positions"][:], gb["positions"][:], equal_nan=True)
    assert np.array_equal(ga["time"][:], gb["time"][:], equal_nan=True)
    assert sorted(p.name for p in (own / "vtk").iterdir()) == sorted(p.name for p in (branch / "vtk").iterdir())
    assert (own / "trajectory.pvd").read_text() == (branch / "trajectory.pvd").read_text()
    # the test differs from the donor's (another drive), so the equality above is not trivial
    assert not np.array_equal(load(donor / "final.npz").points, b.points)

    sa, sb = json.loads((own / "summary.json").read_text()), json.loads((branch / "summary.json").read_text())
    for k in ("contacts_per_rod", "largest_cluster_fraction", "height_kept", "persistence", "stable", "steps"):
        assert sa[k] == sb[k], k
    assert sa["entangled_from"] is None
    rec = sb["entangled_from"]
    manifest = json.loads((donor / "rodwarp-run.json").read_text())
    assert rec["run"] == str(donor.resolve()) and rec["run_id"] == manifest["run_id"]
    assert rec["time"] == pytest.approx(0.3) and rec["steps"] == sa["dt"]["entangle"]["steps"]
    assert sb["dt"]["entangle"]["steps"] == sa["dt"]["entangle"]["steps"]
    assert sb["dt"]["stability"]["wall_s"] > 0


def test_entangled_from_refuses_what_does_not_fit(runs, tmp_path):
    donor = runs / "donor"
    r = run(tmp_path / "g", "--gravity", "1", "--entangled-from", str(donor))
    assert r.returncode == 2 and "differs from this one (gravity)" in r.stderr
    assert not (tmp_path / "g").exists()  # refused before the folder is taken
    r = run(tmp_path / "none", "--entangled-from", str(tmp_path))
    assert r.returncode == 2 and "no entangled.npz there" in r.stderr
    r = run(donor, "--overwrite", "--entangled-from", str(donor))
    assert r.returncode == 2 and "own --out" in r.stderr
    r = run(tmp_path / "e0", "--entangle-duration", "0", "--entangled-from", str(donor))
    assert r.returncode == 2 and "no entangling stage" in r.stderr
    # the donor is unharmed by the refusals
    assert json.loads((donor / "rodwarp-run.json").read_text())["complete"] is True
