"""What a new user meets on the first run (issue 29, class 7).

No CUDA warning on a CPU machine, a word before Warp compiles the kernels (and none when they
are cached), and a trajectory that holds only the frames written.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

TINY = ["simulate", "--alpha", "20", "--n-rods", "12", "--entangle-duration", "0.02", "--duration", "0.02",
        "--save-every", "0.01", "--quiet"]
NOTICE = "compiling Warp kernels"


def _simulate(out: Path, *extra: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rodwarp.cli", *TINY, "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=900, env=env)


def _positions(out: Path) -> tuple[np.ndarray, np.ndarray, int]:
    import zarr

    g = zarr.open_group(str(out / "trajectory.zarr"), mode="r")
    return g["positions"][:], g["time"][:], int(g.attrs["n_frames"])


def test_cpu_run_is_quiet_and_its_trajectory_holds_only_written_frames(tmp_path):
    out = tmp_path / "run"
    r = _simulate(out, "--device", "cpu")
    assert r.returncode == 0, r.stderr
    assert "CUDA" not in r.stderr and "CUDA" not in r.stdout
    pos, t, n = _positions(out)
    # every frame written, none preallocated and left NaN: positions[-1] is the last state
    assert pos.shape[0] == n == t.shape[0] == 5  # start + 2 entangling + 2 test samples
    assert np.isfinite(pos).all() and np.isfinite(t).all()
    assert np.all(np.diff(t) > 0)
    from rodwarp.rodset import load

    assert np.array_equal(pos[-1], load(out / "final.npz").points)
    # xarray (the tests' reader) sees the same frames through the consolidated metadata
    import xarray as xr

    ds = xr.open_zarr(out / "trajectory.zarr")
    assert ds.sizes["frame"] == n and not bool(np.isnan(ds["positions"].values).any())


def test_auto_device_on_a_cpu_machine_says_nothing_about_cuda():
    code = ("from rodwarp import _warp; import warp as wp; print(_warp.resolve_device('auto'), "
            "wp.is_cuda_available())")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    if r.stdout.split()[-1] == "True":
        pytest.skip("this machine has CUDA")
    assert r.stdout.split()[0] == "cpu"
    assert "CUDA" not in r.stderr


def test_asking_for_cuda_without_it_is_one_line(tmp_path):
    import warp as wp

    from rodwarp import _warp

    _warp.init()
    if wp.is_cuda_available():
        pytest.skip("this machine has CUDA")
    r = _simulate(tmp_path / "run", "--device", "cuda")
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "no CUDA device is available" in lines[0]
    assert "Could not find or load" not in r.stderr


def test_finished_trajectory_is_trimmed_and_a_resume_grows_it(tmp_path):
    from rodwarp.rodset.trajectory import Trajectory

    offsets = np.array([0, 3, 6])
    frame = lambda k: np.full((6, 3), float(k))  # noqa: E731
    path = tmp_path / "trajectory.zarr"
    tr = Trajectory(path, 8, offsets, np.array([0.1, 0.1]))
    for k in range(3):
        tr.write(k, 0.1 * k, frame(k))
    # a killed run: the unfinished arrays are still their full length, the tail NaN
    tr = Trajectory(path, 8, offsets, np.array([0.1, 0.1]), resume=True)
    for k in range(2, 6):  # a resume rewrites from its checkpoint's frame on
        tr.write(k, 0.1 * k, frame(k))
    tr.finish()
    pos, t, n = _positions(tmp_path)
    assert n == 6 and pos.shape == (6, 6, 3) and t.shape == (6,)
    assert np.isfinite(pos).all() and pos[-1, 0, 0] == 5.0
    # reopened for another resume, the finished arrays grow back to the run's length
    tr = Trajectory(path, 8, offsets, np.array([0.1, 0.1]), resume=True)
    tr.write(6, 0.6, frame(6))
    tr.finish()
    pos, t, n = _positions(tmp_path)
    assert n == 7 and pos.shape[0] == 7 and np.isfinite(pos).all()


def test_cold_modules_follow_the_cache(tmp_path, monkeypatch):
    import warp as wp

    from rodwarp import _warp

    _warp.init()
    _warp.load_kernels("cpu", progress=False)  # warm (compiles only if this environment is new)
    assert _warp.cold_modules("cpu") == []
    assert _warp.load_kernels("cpu", progress=False) is False
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path))
    assert len(_warp.cold_modules("cpu")) == len(_warp.SIMULATION_MODULES)


@pytest.mark.slow
def test_compile_notice_with_an_empty_kernel_cache_only(tmp_path):
    """Compiles every simulation kernel once (about 20 s on two cores), then runs again cached."""
    cache = tmp_path / "kernel-cache"
    env = dict(os.environ, RODWARP_KERNEL_CACHE=str(cache))
    cold = _simulate(tmp_path / "cold", "--device", "cpu", env=env)
    assert cold.returncode == 0, cold.stderr
    notices = [ln for ln in cold.stderr.splitlines() if NOTICE in ln]
    assert len(notices) == 1 and str(cache) in notices[0] and "first run" in notices[0]
    assert "CUDA" not in cold.stderr
    warm = _simulate(tmp_path / "warm", env=env)  # the default device (auto) this time
    assert warm.returncode == 0, warm.stderr
    assert NOTICE not in warm.stderr
    assert "CUDA" not in warm.stderr
