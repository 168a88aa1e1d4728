"""One command for a machine with an NVIDIA GPU (issue 34): the CUDA tests, CPU/CUDA agreement on
the first simulated second of the main job, and GPU throughput at 1e3, 1e4 and 1e5 rods, all in
at most ``--budget`` seconds (default 480 s: 8 minutes).

    bash scripts/device_check.sh [--budget 480] [--out benchmarks/results/device_check.json]

Without a CUDA device it prints one line on stdout (``device_check: no CUDA device (warp sees
only cpu); nothing measured``), writes nothing and exits 0.  With one it runs, in order:

1. ``cuda_tests``: ``pytest -m cuda tests/`` in a child process (the tests that
   tests/conftest.py skips without a GPU), killed when its allowance runs out; passed / failed / error / skipped
   counts from its JUnit XML.  A GPU machine where no CUDA test passed is a failure.
2. ``agreement``: the first simulated second of ``rodwarp simulate --alpha 100 --freq 10``
   (every default: 540 rigid rods, the entangling drive, 10 Hz and 0.05 m) run through
   :func:`rodwarp.experiments.run_protocol` as the CLI does, with the run plan
   (:func:`rodwarp.experiments.plan`) cut to its first second (:func:`first_second`; on the CPU
   its frames at 0, 0.1, ..., 1 s are bit for bit those of the main job), three times: on
   ``cpu`` (the CPU's path: one sequential Gauss-Seidel launch), on ``cuda:0`` (the GPU's path:
   coloured contacts, one launch per colour and sweep) and on ``cpu`` with the GPU's path
   (``RodSolver(coloring="on")``).  Compared (tolerances and why: :data:`EARLY_TOLERANCES`,
   :data:`LATE_TOLERANCES`):

   * at 0.1 s (63 steps, the horizon of the agreement tests in tests/test_devices.py): the
     largest vertex distance, CUDA against the coloured CPU run within 1e-9 m (the same path:
     round-off) and CUDA against the default CPU run within 1e-3 m (another contact order);
   * at 1 s: the pile's observables the verdict is built from (centroid height, contacts per
     rod, kinetic energy, largest cluster fraction) and the median vertex distance, CUDA
     against the default CPU run.  A shaken granular pile is chaotic: on the CPU, the two
     contact orders put the vertices at most 7e-6 m apart at 0.1 s and 5 d apart (median
     0.09 d) at 1 s, about threefold every 0.1 s, so single vertices are judged only at 0.1 s;
   * the distances every 0.1 s for the three pairs, reported (the CPU's own coloured-vs-default
     pair shows how far a mere change of contact order carries the pile, on the same machine).
3. ``throughput``: settled piles of about 1e3, 1e4 and 1e5 rods made of the benchmarks' settled
   100-rod tile (:func:`benchmarks.common.settled_tile`, :func:`benchmarks.common.tiled_model`)
   timed by the scaling benchmark's own measurement (``benchmarks.bench_scaling._measure``:
   three untimed steps first, then windows of 10 steps from one snapshot, repeated up to 5
   times, median): ms per step and vertex-steps per second.  A size whose predicted cost
   (from the sizes already measured) does not fit the allowance left shrinks by 3 until it
   does (rounded to whole tiles) or is skipped.
4. The results (device, versions, commit, date, command, every number, the checks) go to
   ``--out`` (JSON) and a short Markdown summary next to it (same name, ``.md``), rewritten
   after every step so that an interrupted check keeps what it measured.

Each step gets its share of the budget (:data:`SHARES`) plus whatever the earlier ones left
unused (:func:`step_allowance`); :data:`MARGIN_S` is kept for writing the results.  A watchdog
ends the process (exit 124) if the budget is spent anyway (a cold kernel compile, say).
Progress lines go to stderr.  Exit status: 0 when every step ran and every check passed (or no
GPU), 1 otherwise (the results are written either way), 124 on the watchdog.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))  # benchmarks.common and benchmarks.bench_scaling, imported when used
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "device_check.json"

BUDGET_S = 480.0  # 8 minutes, the whole check
MARGIN_S = 15.0  # kept back from the steps for writing the results and leaving
#: share of the budget (less the margin) of each step; a step also gets what earlier ones left
#: (the tests come first and may compile every kernel module for the GPU on a cold cache)
SHARES = {"cuda_tests": 0.5, "agreement": 0.25, "throughput": 0.25}
STEPS = tuple(SHARES)
SIZES = (1000, 10000, 100000)  # rods of the throughput piles (multiples of the 100-rod tile)
TILE_RODS = 100

#: the main job, ``rodwarp simulate --alpha 100 --freq 10``, every other parameter its default
JOB = {"alpha": 100.0, "freq": 10.0}
HORIZON_S = 1.0  # simulated seconds compared
EARLY_S = 0.1  # s; the first sample of the run, 63 steps of the main job (tests/test_devices.py: 60)
#: largest vertex distance (m) allowed at EARLY_S, by pair of runs:
#: "same_path": CUDA and the CPU running the GPU's path (coloured contacts, launch by launch):
#:   round-off only, tests/test_devices.py::test_pile_cpu_and_cuda_agree_with_coloring (1e-9 m
#:   after 60 steps of a contact-rich pile);
#: "default_paths": CUDA and the CPU as `rodwarp simulate` runs on each (the CPU does not
#:   colour): another contact order, tests/test_devices.py::
#:   test_coloring_is_valid_and_close_to_sequential_gauss_seidel (1e-3 m after 60 steps; on
#:   the CPU the two orders differ by 7e-6 m at 0.1 s of the main job).
EARLY_TOLERANCES = {"same_path": 1e-9, "default_paths": 1e-3}
#: CUDA against the default CPU run after HORIZON_S: (kind, tolerance, why).  Measured once on
#: the CPU alone (the GPU's path, coloured contacts, against the default contact order; Warp
#: 1.19, 2026-12-05): centroid height 0.015 %, contacts per rod 0.07 (2.63 against 2.56),
#: kinetic energy 0.5 %, largest cluster fraction 0.002, median vertex distance 0.09 d (max
#: 5 d).  The tolerances are 4 to 60 times those (for Z over three times the Poisson scatter of
#: the contact count), so a GPU as far from the CPU as another contact order passes, and a
#: wrong pile does not: one that lost contacts or rods, did not fall (the centroid drops by
#: 12 % in this second), or was shaken harder or softer.
LATE_TOLERANCES = {
    "centroid_height": ("relative", 0.01, "mass centroid height (m): 1 % is 1 d; measured 0.015 %"),
    "contacts_per_rod": ("absolute", 0.3, "Z: ~960 contact pairs scatter by sqrt(960) = 3 % (0.08) between "
                                          "chaotic realisations; 0.3 is over 3 of those; measured 0.07"),
    "kinetic_energy": ("relative", 0.10, "kinetic energy (J) of the shaken pile, set by the drive; measured 0.5 %"),
    "largest_cluster_fraction": ("absolute", 0.05, "f, the verdict's cluster fraction; measured 0.002"),
    "median_vertex_distance_d": ("bound", 0.5, "median vertex distance in rod diameters: half the vertices "
                                               "still within half a diameter; measured 0.09 d"),
}
#: metrics.csv columns recorded for each run at HORIZON_S
OBSERVABLES = ("contacts_per_rod", "n_contact_pairs", "kinetic_energy", "centroid_height",
               "largest_cluster_fraction", "max_penetration_over_d")
PYTEST = ("-m", "pytest", "-m", "cuda", "tests/", "-q", "-p", "no:cacheprovider")


def log(msg: str) -> None:
    print(f"[device_check {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------------------------
# pure helpers
# ----------------------------------------------------------------------------------------------

def step_allowance(budget: float, used: float, step: str, steps=STEPS, margin: float = MARGIN_S,
                   shares: dict = SHARES) -> float:
    """Seconds that ``step`` may take.

    Parameters
    ----------
    budget : float
        The whole check's time (s).
    used : float
        Time spent so far, since the check started (s).
    step : str
        The step about to run, one of ``steps``.
    steps : sequence of str
        The steps of this check, in order.
    margin : float
        Time kept back for writing the results (s).
    shares : dict
        Each step's share of ``budget - margin`` (normalised over ``steps``).

    Returns
    -------
    float
        What is left (s) less the shares of the steps after this one: the step's own share
        plus whatever the earlier steps did not use; never negative.
    """
    usable = budget - margin
    total = sum(shares[s] for s in steps)
    later = sum(shares[s] for s in steps[list(steps).index(step) + 1:]) / total * usable
    return max(0.0, usable - used - later)


def affordable_rods(target: int, seconds: float, cost, floor: int = TILE_RODS, tile: int = TILE_RODS) -> int | None:
    """The largest pile of at most ``target`` rods whose measurement fits ``seconds``.

    Parameters
    ----------
    target : int
        Rods wanted (a multiple of ``tile``).
    seconds : float
        Time left for it (s).
    cost : callable
        ``cost(n)``: predicted seconds to build and time a pile of ``n`` rods; None when
        nothing predicts it yet (the size is then tried, if any time is left).
    floor : int
        Fewest rods worth measuring (the previous size measured, plus one tile).
    tile : int
        Rods per tile: sizes are whole tiles.

    Returns
    -------
    int or None
        ``target``, or ``target`` divided by 3, 9, ... (rounded down to whole tiles), the first
        that fits; None when none at or above ``floor`` does.
    """
    n = int(target)
    while n >= max(floor, tile):
        c = cost(n)
        if (c is None and seconds > 0) or (c is not None and c <= seconds):
            return n
        n = (n // 3) // tile * tile
    return None


def distances(a: np.ndarray, b: np.ndarray, diameter: float, within: float = 1e-9) -> dict:
    """How far two runs' vertices are apart.

    Parameters
    ----------
    a, b : (V, 3) array
        Vertex positions of the same rods in two runs (m).
    diameter : float
        Rod diameter (m), the unit of the ``*_d`` entries.
    within : float
        Distance (m) under which a vertex counts as agreeing to round-off.

    Returns
    -------
    dict
        ``max_m`` (m); ``max_d``, ``median_d``, ``p90_d`` (rod diameters); ``fraction_within``
        (of the vertices, closer than ``within``).
    """
    e = np.linalg.norm(np.asarray(a, float) - np.asarray(b, float), axis=1)
    return {"max_m": float(e.max()), "max_d": float(e.max() / diameter), "median_d": float(np.median(e) / diameter),
            "p90_d": float(np.percentile(e, 90) / diameter), "fraction_within": float(np.mean(e < within))}


def judge(name: str, reference: float, value: float, kind: str, tolerance: float, why: str = "") -> dict:
    """One check: ``value`` against ``reference`` (or against ``tolerance`` alone for ``bound``).

    Parameters
    ----------
    name : str
        What is compared.
    reference, value : float
        The CPU's and the GPU's number (``bound``: ``reference`` is unused, ``value`` is the
        measured difference itself).
    kind : {"absolute", "relative", "bound"}
        ``|value - reference| <= tolerance``, ``|value - reference| <= tolerance * |reference|``,
        or ``value <= tolerance``.
    tolerance : float
        In the units of the values (``relative``: a fraction).
    why : str
        Where the tolerance comes from.

    Returns
    -------
    dict
        ``name``, ``cpu``, ``cuda``, ``difference`` (absolute; relative for ``relative``),
        ``kind``, ``tolerance``, ``ok`` and ``why``.
    """
    if kind == "bound":
        diff = float(value)
    elif kind == "absolute":
        diff = abs(float(value) - float(reference))
    elif kind == "relative":
        diff = abs(float(value) - float(reference)) / abs(float(reference)) if reference else math.inf
    else:
        raise ValueError(f"kind must be absolute, relative or bound, got {kind!r}")
    return {"name": name, "cpu": None if kind == "bound" else float(reference), "cuda": float(value),
            "difference": diff, "kind": kind, "tolerance": float(tolerance), "ok": bool(diff <= tolerance),
            "why": why}


def late_checks(cpu_row: dict, cuda_row: dict, apart: dict, tolerances: dict = LATE_TOLERANCES) -> list[dict]:
    """The checks at the end of the compared second (CUDA against the default CPU run).

    Parameters
    ----------
    cpu_row, cuda_row : dict
        metrics.csv rows (numbers) of the two runs at the same time.
    apart : dict
        :func:`distances` of their vertices at that time.
    tolerances : dict
        ``name: (kind, tolerance, why)``; ``median_vertex_distance_d`` is checked against
        ``apart["median_d"]``, the others against the rows' columns of that name.

    Returns
    -------
    list of dict
        One :func:`judge` record per tolerance.
    """
    out = []
    for name, (kind, tol, why) in tolerances.items():
        if name == "median_vertex_distance_d":
            out.append(judge(name, 0.0, apart["median_d"], kind, tol, why))
        else:
            out.append(judge(name, cpu_row[name], cuda_row[name], kind, tol, why))
    return out


def junit_counts(xml_text: str) -> dict:
    """Outcome counts of a pytest JUnit XML report.

    Parameters
    ----------
    xml_text : str
        The report (``pytest --junitxml``).

    Returns
    -------
    dict
        ``tests``, ``passed``, ``failed``, ``errors``, ``skipped`` (counts of test cases) and
        ``not_passed`` (the ids of the failed and errored ones, ``module::name``).
    """
    root = ET.fromstring(xml_text)
    counts = {"tests": 0, "passed": 0, "failed": 0, "errors": 0, "skipped": 0, "not_passed": []}
    for case in root.iter("testcase"):
        counts["tests"] += 1
        tags = {child.tag for child in case}
        name = f"{case.get('classname', '')}::{case.get('name', '')}"
        if "failure" in tags:
            counts["failed"] += 1
            counts["not_passed"].append(name)
        elif "error" in tags:
            counts["errors"] += 1
            counts["not_passed"].append(name)
        elif "skipped" in tags:
            counts["skipped"] += 1
        else:
            counts["passed"] += 1
    return counts


# ----------------------------------------------------------------------------------------------
# the device and the record
# ----------------------------------------------------------------------------------------------

def _nvidia_smi() -> str | None:
    """``name, driver_version, memory.total`` of the first GPU as nvidia-smi prints them."""
    try:
        r = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"],
                           capture_output=True, text=True, timeout=15)
    except (OSError, subprocess.SubprocessError):
        return None
    return (r.stdout.strip().splitlines() or [None])[0] if r.returncode == 0 else None


def _version(v) -> str | None:
    if v is None:
        return None
    return ".".join(str(x) for x in v) if isinstance(v, (tuple, list)) else str(v)


def gpu_info(device: str) -> dict:
    """The GPU as Warp and the driver name it: name, architecture, memory (GiB), versions."""
    import warp as wp

    d = wp.get_device(device)
    return {"warp_device": str(d), "name": d.name, "arch": f"sm_{d.arch}", "sm_count": d.sm_count,
            "memory_gib": round(d.total_memory / 2**30, 1), "cuda_driver": _version(wp.get_cuda_driver_version()),
            "cuda_toolkit_of_warp": _version(wp.get_cuda_toolkit_version()), "nvidia_smi": _nvidia_smi()}


def write_results(record: dict, out: Path) -> None:
    """The record as JSON at ``out`` and its Markdown summary next to it, both atomically."""
    from rodwarp.rodset.files import write_json, write_text

    write_json(out, record)
    write_text(out.with_suffix(".md"), markdown(record))


def _f(x, digits: int = 3) -> str:
    from benchmarks.common import fmt

    return fmt(x, digits)


def markdown(rec: dict) -> str:
    """A short Markdown summary of a device check record."""
    g, v = rec["device"], rec["versions"]
    git = v.get("git") or {}
    lines = [
        "# Device check",
        "",
        f"`{rec['command']}` on {rec['date']}: **{g['name']}** ({g['arch']}, {g['memory_gib']} GiB; CUDA driver "
        f"{g['cuda_driver']}, Warp built with CUDA {g['cuda_toolkit_of_warp']}; nvidia-smi: {g['nvidia_smi'] or '—'}), "
        f"Warp {v['warp']}, rodwarp {v['rodwarp']}, commit {git.get('commit')}"
        f"{' (engine modified)' if git.get('engine_dirty') else ''}; host CPU {v['cpu']}. "
        f"Wall {rec['wall_s']:.0f} s of a {rec['budget_s']:g} s budget"
        f"{'' if rec['complete'] else ' (incomplete: written after a step)'}.",
        "",
        f"**{'All checks passed.' if not rec['problems'] else 'Problems: ' + '; '.join(rec['problems'])}**",
    ]
    ran = {k: s for k, s in rec["steps"].items() if not s.get("error")}
    t = ran.get("cuda_tests")
    if t:
        lines += ["", "## 1. CUDA tests", ""]
        c = t.get("counts") or {}
        lines.append(f"`{t['command']}`: {c.get('passed', '—')} passed, {c.get('failed', '—')} failed, "
                     f"{c.get('errors', '—')} errors, {c.get('skipped', '—')} skipped in {t['wall_s']:.0f} s "
                     f"(allowance {t['allowance_s']:.0f} s){'; timed out' if t.get('timed_out') else ''}."
                     + (f" Not passed: {', '.join(c['not_passed'])}." if c.get("not_passed") else ""))
    a = ran.get("agreement")
    if a:
        lines += ["", "## 2. CPU/CUDA agreement: the first simulated second of "
                      "`rodwarp simulate --alpha 100 --freq 10`", ""]
        runs = a.get("runs", {})
        if runs:
            lines.append("; ".join(f"{k}: {r['steps']} steps, {r['wall_s']:.1f} s wall" for k, r in runs.items())
                         + f" ({a.get('n_rods')} rods, {a.get('n_vertices')} vertices, d = {a.get('diameter_m')} m).")
        if a.get("checks"):
            lines += ["", "| check | CPU | CUDA | difference | tolerance | ok |", "|---|---|---|---|---|---|"]
            for c in a["checks"]:
                kind = {"relative": " (relative)", "absolute": "", "bound": ""}[c["kind"]]
                lines.append(f"| {c['name']} | {_f(c['cpu'])} | {_f(c['cuda'])} | {_f(c['difference'])}{kind} | "
                             f"{_f(c['tolerance'])} | {'yes' if c['ok'] else '**no**'} |")
        if a.get("series"):
            pairs = list(a["series"])
            lines += ["", "Vertex distances, max / median in rod diameters:", "",
                      "| t (s) | " + " | ".join(pairs) + " |", "|---|" + "---|" * len(pairs)]
            for k in range(len(a["series"][pairs[0]])):
                row = [a["series"][p][k] for p in pairs]
                lines.append(f"| {row[0]['t']:.1f} | "
                             + " | ".join(f"{_f(r['max_d'])} / {_f(r['median_d'])}" for r in row) + " |")
        if a.get("note"):
            lines += ["", a["note"]]
    p = ran.get("throughput")
    if p:
        lines += ["", f"## 3. Throughput on {g['warp_device']}", "",
                  "| rods | vertices | ms/step, median (min–max) | vertex-steps/s, median | steps timed | "
                  "contacts/step |", "|---|---|---|---|---|---|"]
        for q in p.get("points", []):
            lines.append(f"| {q['n_rods']:,} | {q['n_vertices']:,} | {_f(q['ms_per_step']['median'])} "
                         f"({_f(q['ms_per_step']['min'])}–{_f(q['ms_per_step']['max'])}) | "
                         f"{_f(q['vertex_steps_per_s']['median'])} | {q['repeats']} x {q['steps_timed']} | "
                         f"{_f(q['contacts_per_step']['mean'])} |")
        for s in p.get("skipped", []):
            lines.append(f"| {s['n_rods']:,} skipped: {s['why']} | | | | | |")
    for name, s in rec["steps"].items():
        if s.get("error"):
            lines += ["", f"Step {name} failed: `{s['error']}`"]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------
# step 1: the CUDA tests
# ----------------------------------------------------------------------------------------------

def cuda_tests(allowance: float) -> dict:
    """``pytest -m cuda tests/`` in a child process, killed after ``allowance`` seconds."""
    rec = {"command": "pytest -m cuda tests/", "allowance_s": allowance, "timed_out": False}
    t = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="device_check_") as tmp:
        xml = Path(tmp) / "junit.xml"
        try:
            r = subprocess.run([sys.executable, *PYTEST, f"--junitxml={xml}"], cwd=ROOT, capture_output=True,
                               text=True, timeout=max(allowance, 1.0))
            rec["exit_code"] = r.returncode
            rec["last_line"] = (r.stdout.strip().splitlines() or [""])[-1]
        except subprocess.TimeoutExpired:
            rec.update(timed_out=True, exit_code=None, last_line=None)
        rec["counts"] = junit_counts(xml.read_text()) if xml.exists() else None
    rec["wall_s"] = time.perf_counter() - t
    c = rec["counts"] or {}
    rec["ok"] = rec["exit_code"] == 0 and c.get("passed", 0) > 0 and not rec["timed_out"]
    if not rec["ok"]:
        rec["why"] = ("timed out" if rec["timed_out"] else f"exit {rec['exit_code']}") + (
            f", {c['passed']} passed, {c['failed']} failed, {c['errors']} errors, {c['skipped']} skipped" if c else "")
    return rec


# ----------------------------------------------------------------------------------------------
# step 2: CPU/CUDA agreement on the main job's first second
# ----------------------------------------------------------------------------------------------

@contextlib.contextmanager
def _gpu_path_solver():
    """Within: the solver that run_protocol builds colours its contacts on any device
    (``RodSolver(coloring="on")``: separate launches per colour and sweep, the GPU's path)."""
    import rodwarp.sim as sim

    plain = sim.RodSolver

    class Coloured(plain):
        built = 0

        def __init__(self, model, **kw):
            kw["coloring"] = "on"
            super().__init__(model, **kw)
            Coloured.built += 1

    sim.RodSolver = Coloured  # rodwarp.experiments._protocol._build imports it at call time
    try:
        yield Coloured
    finally:
        sim.RodSolver = plain


def first_second(device: str, outdir: Path, gpu_path: bool = False) -> dict:
    """The first :data:`HORIZON_S` of the main job on ``device``, as ``rodwarp simulate`` runs it.

    The parameters are ``ProtocolParams(alpha=100, freq=10)`` (every other one its default);
    the run plan is the protocol's own (:func:`rodwarp.experiments.plan`) with its first stage,
    the entangling, cut to :data:`HORIZON_S` and made the plan's test stage (a plan needs one;
    the flag only adds the verdict's reference, it changes no step).

    Parameters
    ----------
    device : str
        Warp device ("cpu", "cuda:0").
    outdir : Path
        The run folder (written by run_protocol).
    gpu_path : bool
        Colour the contacts on the CPU too (:func:`_gpu_path_solver`).

    Returns
    -------
    dict
        ``times`` (s) and ``positions`` (frames, V, 3; m) every ``save_every`` (0.1 s),
        ``rows`` (metrics.csv, numbers), ``summary``, ``diameter`` (m) and ``wall_s``.
    """
    import zarr

    from rodwarp.experiments import ProtocolParams, plan, run_protocol

    checked = ProtocolParams(**JOB, device=device).validate()
    first = dataclasses.replace(plan(checked.params)[0], duration=HORIZON_S, test=True, keep=False)
    t = time.perf_counter()
    with _gpu_path_solver() if gpu_path else contextlib.nullcontext() as coloured:
        summary = run_protocol(checked, outdir, progress=False, stages=(first,))
    if coloured is not None and coloured.built < 1:
        raise RuntimeError("run_protocol did not build the coloured solver")
    wall = time.perf_counter() - t
    g = zarr.open_group(str(outdir / "trajectory.zarr"), mode="r")
    with open(outdir / "metrics.csv", newline="") as fh:
        rows = [{k: (float(v) if v not in ("", None) and k != "stage" else v) for k, v in r.items()}
                for r in csv.DictReader(fh)]
    return {"times": np.asarray(g["time"][:]), "positions": np.asarray(g["positions"][:]), "rows": rows,
            "summary": summary, "diameter": float(checked.params.diameter), "wall_s": wall}


def _run_record(run: dict, device: str, gpu_path: bool) -> dict:
    s = run["summary"]
    last = run["rows"][-1]
    return {"device": device, "contacts": "coloured (the GPU's path)" if gpu_path or device != "cpu"
            else "sequential (the CPU's path)", "wall_s": run["wall_s"], "steps": s["steps"], "dt_s": s["dt"],
            "at_horizon": {k: last[k] for k in OBSERVABLES}}


def agreement(allowance: float, device: str) -> dict:
    """Step 2: the main job's first second on the CPU, on ``device`` and on the CPU with the
    GPU's path; the comparisons and checks of the module docstring."""
    t0 = time.perf_counter()
    rec = {"job": "rodwarp simulate --alpha 100 --freq 10 (defaults), the first second of its entangling stage",
           "horizon_s": HORIZON_S, "early_s": EARLY_S, "allowance_s": allowance, "runs": {}, "checks": [],
           "series": {}, "early_tolerances_m": EARLY_TOLERANCES}
    tmp = Path(tempfile.mkdtemp(prefix="device_check_"))
    runs = {}
    try:
        log("agreement: the first second on cpu")
        runs["cpu"] = first_second("cpu", tmp / "cpu")
        cpu_wall = runs["cpu"]["wall_s"]
        log(f"agreement: cpu {cpu_wall:.1f} s; now on {device}")
        runs["cuda"] = first_second(device, tmp / "cuda")
        left = allowance - (time.perf_counter() - t0)
        # the coloured path launches per colour and sweep: about 4x the CPU's sequential run
        if left > 5 * cpu_wall + 5:
            log(f"agreement: {device} {runs['cuda']['wall_s']:.1f} s; now cpu with the GPU's path")
            runs["cpu_gpu_path"] = first_second("cpu", tmp / "cpu_gpu_path", gpu_path=True)
        else:
            rec["note"] = (f"the CPU run of the GPU's path was skipped: {left:.0f} s left, about "
                           f"{5 * cpu_wall:.0f} s needed; the same-path (1e-9 m) check did not run")
            log(f"agreement: {rec['note']}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    for k, r in runs.items():
        rec["runs"][k] = _run_record(r, device if k == "cuda" else "cpu", k == "cpu_gpu_path")
    cpu, gpu = runs["cpu"], runs["cuda"]
    d = cpu["diameter"]
    rec.update(diameter_m=d, n_rods=int(cpu["summary"]["n_rods"]), n_vertices=int(cpu["positions"].shape[1]))
    if not (np.array_equal(cpu["times"], gpu["times"]) and cpu["positions"].shape == gpu["positions"].shape):
        raise RuntimeError(f"the runs sampled different frames: {cpu['times']} and {gpu['times']}")
    pairs = {"cuda vs cpu": ("cuda", "cpu")}
    if "cpu_gpu_path" in runs:
        pairs.update({"cuda vs cpu (GPU's path)": ("cuda", "cpu_gpu_path"),
                      "cpu (GPU's path) vs cpu": ("cpu_gpu_path", "cpu")})
    for label, (x, y) in pairs.items():
        rec["series"][label] = [{"t": float(t), **distances(runs[x]["positions"][k], runs[y]["positions"][k], d)}
                                for k, t in enumerate(cpu["times"])]
    early = int(np.argmin(np.abs(cpu["times"] - EARLY_S)))
    if "cpu_gpu_path" in runs:
        rec["checks"].append(judge(f"max vertex distance at {EARLY_S:g} s, same path (m)", 0.0,
                                   rec["series"]["cuda vs cpu (GPU's path)"][early]["max_m"], "bound",
                                   EARLY_TOLERANCES["same_path"],
                                   "round-off: tests/test_devices.py::test_pile_cpu_and_cuda_agree_with_coloring"))
    rec["checks"].append(judge(f"max vertex distance at {EARLY_S:g} s, default paths (m)", 0.0,
                               rec["series"]["cuda vs cpu"][early]["max_m"], "bound", EARLY_TOLERANCES["default_paths"],
                               "another contact order: tests/test_devices.py::"
                               "test_coloring_is_valid_and_close_to_sequential_gauss_seidel"))
    rec["checks"] += late_checks(cpu["rows"][-1], gpu["rows"][-1], rec["series"]["cuda vs cpu"][-1])
    rec["wall_s"] = time.perf_counter() - t0
    rec["ok"] = all(c["ok"] for c in rec["checks"]) and "cpu_gpu_path" in runs
    return rec


# ----------------------------------------------------------------------------------------------
# step 3: throughput
# ----------------------------------------------------------------------------------------------

def throughput(allowance: float, device: str, sizes=SIZES) -> dict:
    """Step 3: ms per step and vertex-steps per second of settled piles of ``sizes`` rods on
    ``device``, by the scaling benchmark's measurement; sizes shrink to fit ``allowance``."""
    from benchmarks import bench_scaling, common
    from rodwarp.sim.solver import RodSolver

    t0 = time.perf_counter()
    rec = {"scene": "settled 100-rod tiles (alpha 100, l = 1 m, d = 0.01 m, 10 vertices, steel, mu 0.2) side by "
                    "side 0.05 m apart, floor and outer walls, the tile's velocities kept (benchmarks/bench_scaling.py)",
           "method": "benchmarks.bench_scaling._measure: 3 untimed steps, then windows of "
                     f"{bench_scaling.STEPS} steps from one snapshot (pair list rebuilt at each window's start), "
                     "up to 5 repeats, median; RodSolver(model) defaults, dt = default_dt()",
           "sizes_wanted": list(sizes), "allowance_s": allowance, "points": [], "skipped": []}
    if allowance <= 0:
        rec.update(skipped=[{"n_rods": n, "why": "no time left"} for n in sizes], ok=False, why="no time left",
                   wall_s=0.0)
        return rec
    with contextlib.redirect_stdout(sys.stderr):  # the benchmarks log on stdout
        tile = common.settled_tile(device)
    rec["tile"] = common.tile_description(tile)
    measure_steps = 3 + 2 * bench_scaling.STEPS + 1  # the least _measure takes: pre-roll, one repeat of 2 passes, rebuild
    points = rec["points"]
    for i, target in enumerate(sizes):
        left = allowance - (time.perf_counter() - t0)

        def cost(n):
            if not points:
                return None
            last = points[-1]
            return last["setup_s"] / last["n_rods"] * n + bench_scaling._predict(points, n) * measure_steps

        floor = points[-1]["n_rods"] + TILE_RODS if points else TILE_RODS
        n = affordable_rods(target, left, cost, floor=floor)
        if n is None:
            c = cost(target)
            rec["skipped"].append({"n_rods": target, "why": f"{'predicted %.0f s, ' % c if c else ''}{left:.0f} s left"})
            log(f"throughput: N={target} skipped ({rec['skipped'][-1]['why']})")
            continue
        if n != target:
            log(f"throughput: N={target} shrunk to N={n} to fit {left:.0f} s")
        t = time.perf_counter()
        model = common.tiled_model(tile, n // TILE_RODS, device=device, velocities=True)
        dt = RodSolver(model).default_dt()
        setup = time.perf_counter() - t
        # an equal part of what is left for each size still to come (a small pile takes less and
        # leaves the rest to the larger ones); _measure fits its timed passes to it, 0.8 of it
        # leaves room for its untimed steps
        part = 0.8 * (left - setup) / (len(sizes) - i)
        with contextlib.redirect_stdout(sys.stderr):
            r = bench_scaling._measure(model, dt, False, device, max(part, 1.0))
        r.update({"n_rods": model.n_rods, "n_rods_wanted": target, "n_vertices": model.n_vertices, "dt_s": dt,
                  "setup_s": setup, "wall_s": time.perf_counter() - t})
        points.append(r)
        log(f"throughput: N={model.n_rods}: {r['ms_per_step']['median']:.3g} ms/step, "
            f"{r['vertex_steps_per_s']['median']:.3g} vertex-steps/s ({r['repeats']} x {r['steps_timed']} steps, "
            f"{r['wall_s']:.0f} s)")
        del model
    rec["wall_s"] = time.perf_counter() - t0
    rec["ok"] = bool(points)
    if not points:
        rec["why"] = "no pile size fitted the time left"
    return rec


# ----------------------------------------------------------------------------------------------
# the command
# ----------------------------------------------------------------------------------------------

def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="scripts/device_check.sh", description=__doc__.split("\n\n")[0],
                                epilog="Without a CUDA device: one line on stdout, nothing written, exit 0.")
    p.add_argument("--budget", type=float, default=BUDGET_S,
                   help=f"seconds for the whole check (default {BUDGET_S:g}: 8 minutes)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT,
                   help="results JSON (default benchmarks/results/device_check.json); the Markdown summary goes "
                        "next to it with the suffix .md")
    p.add_argument("--steps", default=",".join(STEPS),
                   help=f"comma-separated steps to run, in this order (default {','.join(STEPS)})")
    p.add_argument("--sizes", default=",".join(str(n) for n in SIZES),
                   help="rods of the throughput piles, multiples of 100 (default %(default)s)")
    p.add_argument("--device", default="cuda:0", help="the CUDA device checked (default cuda:0)")
    return p


def main(argv=None) -> int:
    t_start = time.perf_counter()
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = _parser()
    args = ap.parse_args(argv)
    steps = tuple(s.strip() for s in args.steps.split(",") if s.strip())
    if not steps or any(s not in STEPS for s in steps):
        ap.error(f"--steps: choose among {', '.join(STEPS)}")
    sizes = tuple(int(s) for s in args.sizes.split(","))
    if any(n < TILE_RODS or n % TILE_RODS for n in sizes):
        ap.error("--sizes: multiples of 100 rods")
    if args.budget <= MARGIN_S:
        ap.error(f"--budget must exceed {MARGIN_S:g} s")

    from rodwarp import _warp

    _warp.init()
    import warp as wp

    if not wp.is_cuda_available():
        seen = ", ".join(str(d) for d in wp.get_devices()) or "no device"
        print(f"device_check: no CUDA device (warp sees only {seen}); nothing measured")
        return 0

    from benchmarks import common

    device = _warp.resolve_device(args.device)
    out = args.out
    via = os.environ.get("DEVICE_CHECK_WRAPPER")
    rec = {"name": "device_check", "title": "Device check: CUDA tests, CPU/CUDA agreement, GPU throughput",
           "command": f"{via or 'python scripts/device_check.py'} {' '.join(common.command_arg(a) for a in argv)}".strip(),
           "date": common.utc_now(), "device": gpu_info(device), "versions": common.versions(),
           "budget_s": args.budget, "steps_run": list(steps), "steps": {},
           "problems": [], "complete": False, "wall_s": 0.0}
    log(f"{rec['device']['name']} ({device}), budget {args.budget:g} s, steps {', '.join(steps)} -> {common.command_arg(str(out))}")

    def overrun():
        log(f"budget of {args.budget:g} s spent: stopping; {common.command_arg(str(out))} holds the steps done")
        os._exit(124)

    watchdog = threading.Timer(max(args.budget - (time.perf_counter() - t_start), 1.0), overrun)
    watchdog.daemon = True
    watchdog.start()
    for step in steps:
        allowance = step_allowance(args.budget, time.perf_counter() - t_start, step, steps)
        log(f"step {step}: {allowance:.0f} s allowed")
        try:
            if step == "cuda_tests":
                res = cuda_tests(allowance)
            elif step == "agreement":
                res = agreement(allowance, device)
            else:
                res = throughput(allowance, device, sizes)
        except Exception as e:  # noqa: BLE001 - one failing step must not lose the others
            import traceback

            traceback.print_exc()
            res = {"ok": False, "error": f"{type(e).__name__}: {e}".splitlines()[0]}
        rec["steps"][step] = res
        if not res.get("ok"):
            why = res.get("error") or res.get("why") or ""
            if step == "agreement" and res.get("checks"):
                why = "; ".join([c["name"] for c in res["checks"] if not c["ok"]] + [res.get("note") or ""]).strip("; ")
            rec["problems"].append(f"{step} failed" + (f": {why}" if why else ""))
        log(f"step {step}: {'ok' if res.get('ok') else 'FAILED'} ({time.perf_counter() - t_start:.0f} s so far)")
        rec["wall_s"] = time.perf_counter() - t_start
        write_results(rec, out)
    watchdog.cancel()
    rec["complete"] = True
    rec["wall_s"] = time.perf_counter() - t_start
    write_results(rec, out)
    log(f"done in {rec['wall_s']:.0f} s: {'all checks passed' if not rec['problems'] else '; '.join(rec['problems'])}")
    return 0 if not rec["problems"] else 1


if __name__ == "__main__":
    sys.exit(main())
