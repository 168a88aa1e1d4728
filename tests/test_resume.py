"""A killed run resumes from its checkpoint and ends bit for bit where an uninterrupted run ends."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from rodwarp.rodset import load

ARGS = ["simulate", "--alpha", "20", "--n-rods", "40", "--entangle-duration", "0.3", "--duration", "0.3",
        "--save-every", "0.05", "--checkpoint-every", "0.05", "--seed", "5", "--device", "cpu", "--quiet"]


def run(out: Path, extra=()):
    return subprocess.run([sys.executable, "-m", "rodwarp.cli", *ARGS, "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=600)


def test_kill_and_resume_is_bit_exact(tmp_path):
    ref = tmp_path / "ref"
    r = run(ref)
    assert r.returncode == 0, r.stderr

    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "rodwarp.cli", *ARGS, "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    # kill once the run is well into the stability stage (a mid-stage checkpoint exists)
    while time.time() < deadline and proc.poll() is None:
        ck = sorted((out / "checkpoints").glob("ckpt_*.npz")) if (out / "checkpoints").exists() else []
        if len(ck) >= 2 and (out / "metrics.csv").exists() and "stability" in (out / "metrics.csv").read_text():
            os.kill(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.05)
    proc.wait()
    assert proc.returncode != 0, "the run finished before it could be killed; lengthen it"
    assert not (out / "final.npz").exists()
    # everything written so far is readable
    assert (out / "metrics.csv").read_text().startswith("time,")
    import zarr
    g = zarr.open_group(str(out / "trajectory.zarr"), mode="r")
    n = g.attrs["n_frames"]
    assert n >= 2 and np.all(np.isfinite(g["positions"][:n]))

    # the killed run owns its folder: a new run there is refused, naming --resume; resuming
    # with other parameters is refused (--resume continues only its own run)
    r = run(out)
    assert r.returncode == 2 and "holds an unfinished simulate run" in r.stderr and "--resume" in r.stderr
    r = run(out, ["--resume", "--gravity", "0.6"])
    assert r.returncode == 2 and "continues only its own run" in r.stderr and "gravity 0.5 there, 0.6 here" in r.stderr
    # temporaries a kill leaves behind are removed by the resumed run
    (out / ".metrics.csv.k1ll3d.tmp").write_text("torn")
    (out / "vtk" / ".frame_00002.vtp.k1ll3d.tmp").write_text("torn")

    r = run(out, ["--resume"])
    assert r.returncode == 0, r.stderr
    assert not (out / ".metrics.csv.k1ll3d.tmp").exists() and not (out / "vtk" / ".frame_00002.vtp.k1ll3d.tmp").exists()
    import json

    m = json.loads((out / "rodwarp-run.json").read_text())
    assert m["complete"] is True and m["resumed"] == 1
    a = load(ref / "final.npz")
    b = load(out / "final.npz")
    assert np.array_equal(a.points, b.points)
    assert np.array_equal(a.velocities, b.velocities)
    ma = (ref / "metrics.csv").read_text().splitlines()
    mb = (out / "metrics.csv").read_text().splitlines()
    assert ma == mb  # the whole time series, not only the end
    # the resumed trajectory holds every frame once and no unwritten (NaN) ones: as many
    # frames as samples, the same as the uninterrupted run's, its last the final state
    ga = zarr.open_group(str(ref / "trajectory.zarr"), mode="r")
    gb = zarr.open_group(str(out / "trajectory.zarr"), mode="r")
    assert gb["positions"].shape[0] == gb.attrs["n_frames"] == len(mb) - 1
    assert np.isfinite(gb["positions"][:]).all()
    assert np.array_equal(ga["positions"][:], gb["positions"][:])
    assert np.array_equal(gb["positions"][-1], b.points)


def test_resume_without_checkpoint_fails_clearly(tmp_path):
    r = run(tmp_path / "none", ["--resume"])
    assert r.returncode == 2
    assert "nothing to resume" in r.stderr
