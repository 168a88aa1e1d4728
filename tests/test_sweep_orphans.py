"""A sweep's worker processes end with the sweep, however it ends: ``kill -9`` while they start
or while points run, Ctrl-C, SIGTERM, a normal end (issue 47).

Each case starts a real ``rodwarp sweep`` of tiny points in a session of its own, so every
process it starts (workers, multiprocessing's resource tracker) is found by its session id
even after the sweep is gone, and waits until none of them is left.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signals are Linux's")

#: two tiny points (about 2 s each on a CPU core) on two workers
SWEEP = ["sweep", "--alpha", "20,30", "--freq", "1", "--entangle-duration", "0.02", "--duration", "0.02",
         "--save-every", "0.01", "--workers", "2", "--device", "cpu", "--quiet", "--no-figures", "--set", "n_rods=12"]
#: the same points, long enough (about half a minute each) that an interruption surely lands while
#: they run: with SWEEP's points both could finish, and the sweep exit 0, between seeing a point's
#: folder and the signal (seen once in CI)
SWEEP_LONG = [*SWEEP[:SWEEP.index("--duration")], "--duration", "60", "--save-every", "0.5",
              *SWEEP[SWEEP.index("--save-every") + 2:]]
#: the longest a sweep's processes may outlive it (s); they are gone in about a second
GONE_WITHIN = 30.0
#: the longest a sweep may take to start a worker or a point (s): a few seconds, many more on a
#: machine busy with other work
STARTS_WITHIN = 120.0


def _start(tmp_path: Path, args=SWEEP) -> subprocess.Popen:
    """``rodwarp sweep`` in a new session (its id is the sweep's pid), its output in tmp_path."""
    exe = Path(sys.executable).with_name("rodwarp")
    log = open(tmp_path / "sweep.log", "wb")  # a file, not a pipe: a worker must not block on a full pipe
    return subprocess.Popen([str(exe), *args, "--out", str(tmp_path / "sw")], stdout=log, stderr=log,
                            stdin=subprocess.DEVNULL, start_new_session=True)


def _session(sid: int) -> list[psutil.Process]:
    """Live processes (zombies left out) of the session ``sid``."""
    out = []
    for proc in psutil.process_iter():
        try:
            if os.getsid(proc.pid) == sid and proc.status() != psutil.STATUS_ZOMBIE:
                out.append(proc)
        except (OSError, psutil.Error):
            continue
    return out


def _workers(sweep: subprocess.Popen) -> list[psutil.Process]:
    """The sweep's worker processes started so far (multiprocessing's spawned children)."""
    try:
        kids = psutil.Process(sweep.pid).children(recursive=True)
    except psutil.Error:
        return []
    found = []
    for k in kids:
        try:
            if "spawn_main" in " ".join(k.cmdline()):
                found.append(k)
        except psutil.Error:
            continue
    return found


def _wait(condition, timeout: float, what: str, sweep: subprocess.Popen, tmp_path: Path):
    """``condition()`` once it is true; a failure, with the sweep's output, when the sweep
    ends first or ``timeout`` s pass."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout and sweep.poll() is None:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    sweep.kill()
    pytest.fail(f"no {what} within {time.monotonic() - t0:.0f} s (sweep exit code {sweep.poll()}); the sweep said: "
                f"{(tmp_path / 'sweep.log').read_text()[-800:]}")


def _point_running(tmp_path: Path) -> bool:
    points = tmp_path / "sw" / "points"
    return points.is_dir() and any(any(p.iterdir()) for p in points.iterdir() if p.is_dir())


def _left_behind(sweep: subprocess.Popen, seen: list[psutil.Process]) -> tuple[float, list[str]]:
    """Wait for the sweep and every process it started to end; the seconds that took and,
    after :data:`GONE_WITHIN` s, the processes still running (their pids and command lines)."""
    t0 = time.monotonic()
    left = []
    while time.monotonic() - t0 < GONE_WITHIN:
        sweep.poll()
        left = [p for p in {*seen, *_session(sweep.pid)} if _running(p)]
        if sweep.returncode is not None and not left:
            return time.monotonic() - t0, []
        time.sleep(0.05)
    described = []
    for p in left:
        try:
            described.append(f"{p.pid} {' '.join(p.cmdline())[:100]}")
        except psutil.Error:
            continue
        p.kill()  # not left to the next test
    sweep.kill()
    return time.monotonic() - t0, described


def _running(p: psutil.Process) -> bool:
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def test_kill_9_while_workers_start_leaves_no_process(tmp_path):
    sweep = _start(tmp_path)
    seen = _wait(lambda: _workers(sweep), STARTS_WITHIN, "worker process", sweep, tmp_path)
    os.kill(sweep.pid, signal.SIGKILL)  # the first worker is still importing: Dask does not watch its parent yet
    took, left = _left_behind(sweep, seen)
    assert not left, f"{len(left)} process(es) outlived the killed sweep by {took:.0f} s: {left}"


def test_kill_9_while_points_run_leaves_no_process(tmp_path):
    sweep = _start(tmp_path)
    _wait(lambda: _point_running(tmp_path), STARTS_WITHIN, "point running", sweep, tmp_path)
    seen = _workers(sweep)
    assert seen and sweep.poll() is None
    os.kill(sweep.pid, signal.SIGKILL)
    took, left = _left_behind(sweep, seen)
    assert not left, f"{len(left)} process(es) outlived the killed sweep by {took:.0f} s: {left}"


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm"])
def test_interrupted_sweep_leaves_no_process(tmp_path, how):
    sweep = _start(tmp_path, SWEEP_LONG)
    _wait(lambda: _point_running(tmp_path), STARTS_WITHIN, "point running", sweep, tmp_path)
    seen = _workers(sweep)
    assert seen and sweep.poll() is None
    if how == "ctrl-c":  # the terminal signals the whole foreground process group
        os.killpg(sweep.pid, signal.SIGINT)
    else:
        os.kill(sweep.pid, signal.SIGTERM)
    took, left = _left_behind(sweep, seen)
    assert not left, f"{len(left)} process(es) outlived the sweep ({how}) by {took:.0f} s: {left}"
    assert sweep.returncode != 0


def test_finished_sweep_leaves_no_process(tmp_path):
    sweep = _start(tmp_path)
    seen = _wait(lambda: _workers(sweep), STARTS_WITHIN, "worker process", sweep, tmp_path)
    sweep.wait(timeout=120)
    took, left = _left_behind(sweep, seen)
    assert sweep.returncode == 0, (tmp_path / "sweep.log").read_text()[-500:]
    assert not left, f"{len(left)} process(es) outlived the finished sweep: {left}"


def test_each_worker_is_set_to_die_with_the_sweep():
    """Linux kills a worker of the sweep's cluster (SIGKILL) when the sweep process ends,
    whatever the worker is doing: its parent-death signal is set."""
    from rodwarp.experiments._sweep import SWEEP_PID_ENV, _sweep_cluster

    with _sweep_cluster(1) as client:
        got = client.run(_parent_death_signal)
        assert os.environ[SWEEP_PID_ENV] == str(os.getpid())  # only while the cluster runs
    assert list(got.values()) == [signal.SIGKILL]
    assert SWEEP_PID_ENV not in os.environ


def _parent_death_signal() -> int:
    """This process's parent-death signal (prctl PR_GET_PDEATHSIG), 0 for none."""
    import ctypes

    sig = ctypes.c_int(0)
    ctypes.CDLL(None, use_errno=True).prctl(2, ctypes.byref(sig), 0, 0, 0)  # 2: PR_GET_PDEATHSIG
    return sig.value
