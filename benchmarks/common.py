"""Shared helpers of the benchmarks: provenance, repeated timing, scenes, chart output."""

from __future__ import annotations

import functools
import json
import math
import os
import platform
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"

# Steel rods of the paper's protocol: l = 1 m, d = l / alpha.
LENGTH = 1.0
PROTOCOL_HEIGHT = 2.5  # m; the paper drops N = 5.4 alpha rods into a 1 x 1 x 2.5 box (units of l)


def log(msg: str) -> None:
    print(f"[bench {time.strftime('%H:%M:%S')}] {msg}", flush=True)


# ----------------------------------------------------------------------------------------------
# provenance
# ----------------------------------------------------------------------------------------------

def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def git_info() -> dict:
    def git(*args):
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    commit = git("rev-parse", "--short=12", "HEAD")
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", "rodwarp", "kernels")
    return {"commit": commit or None, "engine_dirty": bool(dirty),
            "dirty_files": [ln[3:] for ln in dirty.splitlines()] if dirty else []}


def versions() -> dict:
    import numpy
    import scipy
    import warp

    import rodwarp

    return {
        "rodwarp": rodwarp.__version__,
        "git": git_info(),
        "warp": warp.config.version,
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu": cpu_model(),
        "logical_cpus": os.cpu_count(),
    }


def device_name(device: str) -> str:
    """Human-readable device: the GPU's name, or the CPU model (Warp runs CPU kernels on one thread)."""
    import warp as wp

    from rodwarp import _warp

    dev = _warp.resolve_device(device)
    d = wp.get_device(dev)
    if d.is_cpu:
        return f"cpu: {cpu_model()} (Warp CPU kernels run on one thread)"
    return f"{dev}: {d.name}"


def short_device(rec: dict) -> str:
    """Device without the parenthesised remark, for chart titles and table cells."""
    return (rec.get("device") or "").split(" (")[0]


def command_arg(arg: str) -> str:
    """A command-line argument as a record shows it: a path inside the current folder relative to
    it, so the record names no folder of the machine it ran on."""
    try:
        return Path(arg).resolve().relative_to(Path.cwd().resolve()).as_posix() if Path(arg).is_absolute() else arg
    except ValueError:
        return arg


def utc_now() -> str:
    return datetime.now(timezone.utc).replace(microsecond=0).isoformat()


# ----------------------------------------------------------------------------------------------
# timing
# ----------------------------------------------------------------------------------------------

def n_repeats(quick: bool) -> int:
    """Timing repeats: 3 in quick mode, 5 in full mode."""
    return 3 if quick else 5


def sync(device: str) -> None:
    import warp as wp

    wp.synchronize_device(device)


def spread(samples) -> dict:
    """Median and spread of repeated measurements (min, max, all samples)."""
    a = np.asarray([s for s in samples if s is not None and math.isfinite(s)], dtype=float)
    if a.size == 0:
        return {"median": None, "min": None, "max": None, "n": 0, "samples": []}
    return {"median": float(np.median(a)), "min": float(a.min()), "max": float(a.max()), "n": int(a.size),
            "samples": [float(x) for x in a]}


def time_repeats(fn, repeats: int, *, setup=None, device: str | None = None, warmup: bool = False) -> dict:
    """Call ``setup()`` (untimed) then ``fn()`` (timed, wall clock) ``repeats`` times; with
    ``warmup`` one untimed call first (imports, allocations, compilation)."""
    if warmup:
        if setup is not None:
            setup()
        fn()
    out = []
    for _ in range(repeats):
        if setup is not None:
            setup()
        if device is not None:
            sync(device)
        t = time.perf_counter()
        fn()
        if device is not None:
            sync(device)
        out.append(time.perf_counter() - t)
    return spread(out)


def loglog_slope(xs, ys) -> float | None:
    """Least-squares slope of log y against log x (None with fewer than 2 points)."""
    pts = [(x, y) for x, y in zip(xs, ys) if x and y and x > 0 and y > 0]
    if len(pts) < 2:
        return None
    x = np.log([p[0] for p in pts])
    y = np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


# ----------------------------------------------------------------------------------------------
# stepping
# ----------------------------------------------------------------------------------------------

def new_state_like(model, state):
    from rodwarp.sim.state import State

    s = State(model)
    s.copy_from(state)
    return s


def copy_contacts(solver, points=None):
    """A copy of ``points`` (default the solver's :attr:`default_contacts`, those a step without
    contacts uses): with a state copy, a snapshot that replays bit for bit."""
    out = solver.contacts()
    out.copy_from(solver.default_contacts if points is None else points)
    return out


def restore_contacts(solver, snapshot) -> None:
    """Put a :func:`copy_contacts` snapshot back as the solver's default contacts."""
    solver.default_contacts.copy_from(snapshot)


def advance(solver, a, b, dt: float, n: int, callback=None):
    """``n`` steps ping-ponging states ``a`` and ``b``; returns (current, scratch, last StepInfo)."""
    info = None
    for _ in range(n):
        info = solver.step(a, b, dt=dt)
        a, b = b, a
        if callback is not None:
            callback(a, info)
    return a, b, info


# ----------------------------------------------------------------------------------------------
# scenes
# ----------------------------------------------------------------------------------------------

def protocol_box(n_rods: int, alpha: float) -> np.ndarray:
    """Box of the settling piles (m).

    The paper drops N0 = 5.4 alpha rods of length l into a 1 x 1 x 2.5 box (units of l).  For
    N rods we keep the height 2.5 l and scale both horizontal sides by sqrt(N / N0), which
    keeps the number density; the sides are never below l (1 m), so for N < N0 the box is
    the paper's 1 x 1 x 2.5 box and the pile is more dilute than the protocol.
    """
    side = max(1.0, math.sqrt(n_rods / (5.4 * alpha)))
    return np.array([side * LENGTH, side * LENGTH, PROTOCOL_HEIGHT * LENGTH])


def pile_model(n_rods: int, diameter: float, box, *, seed: int = 0, device: str = "cpu", mu: float = 0.2,
               n_vertices: int = 10):
    """Random (RSA) steel packing in ``box`` with floor and four side walls, gravity -z."""
    from rodwarp.sim.builder import ModelBuilder
    from rodwarp.sim.model import STEEL
    from rodwarp.experiments import random_packing

    rods = random_packing(n_rods, LENGTH, diameter, box, seed=seed, device=device, n_vertices=n_vertices)
    builder = ModelBuilder(rods, STEEL, gravity=(0.0, 0.0, -9.81), mu=mu, device=device)
    builder.add_box(np.zeros(3), np.asarray(box, float), walls=("floor", "x-", "x+", "y-", "y+"))
    model = builder.finalize()
    return model


TILE = {"n_rods": 100, "diameter": 0.01, "box": (1.0, 1.0, 0.6), "duration": 0.6, "seed": 1}


@functools.lru_cache(maxsize=4)
def settled_tile(device: str = "cpu", diameter: float = TILE["diameter"], duration: float = TILE["duration"]) -> dict:
    """A settled, contact-rich pile of 100 steel rods (alpha = l/d), computed once per process.

    100 rods are placed by RSA in a 1 x 1 x 0.6 m box (lower than the protocol's 2.5 m so the
    pile lands within ``duration``) with floor and side walls, and simulated with the
    default solver for ``duration`` s.  Used as the contact-rich configuration of the
    broadphase benchmark, the dense pile point and the iteration sweep; tiling it side by side
    gives settled piles of any size without simulating them.
    """
    from rodwarp.rodset import contacts_per_rod
    from rodwarp.sim import centroid_height, rod_contacts
    from rodwarp.sim.solver import RodSolver

    box = np.array(TILE["box"], float)
    model = pile_model(TILE["n_rods"], diameter, box, seed=TILE["seed"], device=device)
    solver = RodSolver(model)
    dt = solver.default_dt()
    t0 = time.perf_counter()
    a = model.state()
    b = new_state_like(model, a)
    a, b, info = advance(solver, a, b, dt, int(round(duration / dt)))
    wall = time.perf_counter() - t0
    z = contacts_per_rod(model.n_rods, rod_contacts(model, a, solver.default_contacts))
    log(f"settled tile: {model.n_rods} rods, d = {diameter} m, {duration} s in {wall:.1f} s, Z = {z:.2f}")
    return {
        "rest_points": model.rods.points.copy(),
        "points": a.positions(),
        "velocities": a.velocities(),
        "offsets": model.rods.offsets.copy(),
        "radius": 0.5 * diameter,
        "box": box,
        "dt": dt,
        "time": a.time,
        "Z": z,
        "centroid_height": centroid_height(model, a),
        "contacts": int(info.n_contacts),
        "wall_s": wall,
        "model": model,
        "state": a,
        "contact_points": copy_contacts(solver),  # the warm start of the state's last step
    }


def tile_description(tile: dict) -> dict:
    return {"n_rods": int(len(tile["offsets"]) - 1), "alpha": LENGTH / (2 * tile["radius"]),
            "box_m": [float(x) for x in tile["box"]], "settle_time_s": float(tile["time"]),
            "dt_s": float(tile["dt"]), "Z": float(tile["Z"]), "centroid_height_m": float(tile["centroid_height"]),
            "contacts_last_step": tile["contacts"], "seed": TILE["seed"]}


def tiled_rods(tile: dict, n_tiles: int, gap: float = 0.05, velocities: bool = False):
    """``n_tiles`` copies of a settled tile side by side on a near-square grid (tile pitch = box
    side + ``gap``), as one RodSet with the straight rest shape; the box spans them all."""
    from rodwarp.rodset import RodSet

    box = tile["box"]
    nx = int(math.ceil(math.sqrt(n_tiles)))
    ny = int(math.ceil(n_tiles / nx))
    pitch = np.array([box[0] + gap, box[1] + gap, 0.0])
    pts, rest, vel, offs = [], [], [], [0]
    n_per = len(tile["offsets"]) - 1
    for k in range(n_tiles):
        shift = pitch * np.array([k % nx, k // nx, 0])
        pts.append(tile["points"] + shift)
        rest.append(tile["rest_points"] + shift)
        vel.append(tile["velocities"])
    V = len(tile["points"])
    offsets = np.concatenate([tile["offsets"][:-1] + k * V for k in range(n_tiles)] + [[n_tiles * V]])
    hi = np.array([nx * pitch[0] - gap, ny * pitch[1] - gap, box[2]])
    rods = RodSet(np.concatenate(pts), offsets, np.full(n_per * n_tiles, tile["radius"]),
                  rest_points=np.concatenate(rest), velocities=np.concatenate(vel) if velocities else None,
                  box=np.stack([np.zeros(3), hi]))
    return rods


def tiled_model(tile: dict, n_tiles: int, device: str = "cpu", velocities: bool = False):
    """Model of ``n_tiles`` settled tiles: steel, mu 0.2, gravity -z, floor and the outer walls."""
    from rodwarp.sim.builder import ModelBuilder
    from rodwarp.sim.model import STEEL

    rods = tiled_rods(tile, n_tiles, velocities=velocities)
    builder = ModelBuilder(rods, STEEL, gravity=(0.0, 0.0, -9.81), mu=0.2, device=device)
    builder.add_box(rods.box[0], rods.box[1], walls=("floor", "x-", "x+", "y-", "y+"))
    model = builder.finalize()
    return model


# ----------------------------------------------------------------------------------------------
# charts
# ----------------------------------------------------------------------------------------------

def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: Path) -> str:
    """Save a figure as PNG atomically; returns the file name."""
    from rodwarp.rodset.files import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    pyplot().close(fig)
    return path.name


def fmt(x, digits: int = 3) -> str:
    """Compact number formatting for tables and readings."""
    if x is None:
        return "—"
    if isinstance(x, (int, np.integer)):
        return f"{x:,}"
    if x == 0:
        return "0"
    a = abs(x)
    if 1e-3 <= a < 1e5:
        return f"{x:.{digits}g}"
    return f"{x:.{max(digits - 1, 1)}e}"


def fmt_spread(s: dict, scale: float = 1.0, unit: str = "", digits: int = 3) -> str:
    """'median (min–max) unit' of a spread dict."""
    if not s or s.get("median") is None:
        return "—"
    u = f" {unit}" if unit else ""
    return f"{fmt(s['median'] * scale, digits)}{u} ({fmt(s['min'] * scale, digits)}–{fmt(s['max'] * scale, digits)})"


def scale_spread(s: dict, k: float) -> dict:
    """A spread dict with every value multiplied by k (k > 0)."""
    if s.get("median") is None:
        return dict(s)
    return {"median": s["median"] * k, "min": s["min"] * k, "max": s["max"] * k, "n": s["n"],
            "samples": [x * k for x in s["samples"]]}


def inverse_spread(s: dict, k: float = 1.0) -> dict:
    """Spread of k / x (rates from times): min and max swap."""
    if s.get("median") is None:
        return dict(s)
    return {"median": k / s["median"], "min": k / s["max"], "max": k / s["min"], "n": s["n"],
            "samples": [k / x for x in s["samples"]]}


def python_command() -> str:
    return "python -m benchmarks " + " ".join(sys.argv[1:])


def simulate_once(out: Path, args: list[str], tag: str) -> tuple[dict | None, str | None]:
    """``rodwarp simulate ARGS --out OUT`` in a fresh process unless OUT already holds a finished
    run (its summary is reused); a run cut short resumes from its checkpoint, or starts again.
    Returns (summary.json, None) or (None, the error's last line)."""
    out = Path(out)
    if not (out / "summary.json").exists():
        cmd = [sys.executable, "-m", "rodwarp.cli", "simulate", *args, "--device", "cpu", "--quiet", "--out", str(out)]
        if out.exists():
            cmd.append("--resume" if (out / "checkpoints").exists() else "--overwrite")
        t = time.time()
        r = subprocess.run(cmd, capture_output=True, text=True)
        err = r.stderr.strip()
        log(f"{tag}: {out.name}: {'ok' if r.returncode == 0 else err[-300:]} ({time.time() - t:.0f} s)")
        if r.returncode != 0:
            return None, (err.splitlines() or ["failed"])[-1]
    return json.loads((out / "summary.json").read_text()), None

