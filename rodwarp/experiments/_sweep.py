"""Parameter sweeps of the rod-packing experiment on Dask.

One point of a sweep is one ``simulate`` run (:func:`rodwarp.experiments.run_protocol`) followed
by ``analyze`` of its final packing, executed as a single task on a ``dask.distributed``
cluster: a :class:`distributed.LocalCluster` of worker processes on this machine (loopback
only, no dashboard) by default, or an existing cluster when a scheduler address is given.

Layout of a sweep directory ``OUT``::

    OUT/sweep.json        the spec, the command, versions, counts
    OUT/results.csv       one row per point (rewritten atomically after every point)
    OUT/points/<id>/      each point's full simulate output, with analyze output in analysis/
    OUT/phase_*.png       figures of :func:`~rodwarp.experiments.phase_diagram` (drawn from
                          results.csv by ``_phase``), OUT/alpha_star.csv

Running the same sweep again skips points whose row has ``status`` ``ok``; a failed point is
recorded with its one-line error and the others go on. Results are plain CSV/JSON files.

The local cluster has at most one worker per core this process may use and no more than memory
holds (:func:`worker_limit`), and its worker processes end with the sweep however it ends
(:func:`_die_with_sweep`).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import logging
import math
import os
import socket
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from rodwarp.errors import RodwarpError
from rodwarp.rodset.commands import SWEEP_OUTPUTS
from rodwarp.experiments._cluster import LOCAL_CLUSTER, _connect, _local_cluster  # noqa: F401 (tests import them here)

#: environment variable that names the sweep process (its pid) to the worker processes of its
#: local cluster (:func:`_die_with_sweep`)
SWEEP_PID_ENV = "RODWARP_SWEEP_PID"
#: Linux prctl(2) option that sets the signal a process gets when its parent ends
_PR_SET_PDEATHSIG = 1


def _ended(pid: int) -> bool:
    """The process ``pid`` has ended: it is gone, or a zombie its parent has not reaped yet."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except (OSError, IndexError):
        return True


def _die_with_sweep() -> None:
    """In a worker process of a sweep's local cluster: be killed (SIGKILL) when the sweep
    process that started it ends, however it ends (``kill -9`` included).

    :func:`_sweep_cluster` names the sweep in :data:`SWEEP_PID_ENV` while its cluster runs. A
    process whose parent is that sweep asks Linux for a parent-death signal
    (``prctl(PR_SET_PDEATHSIG, SIGKILL)``); one whose sweep has already ended (it was given to
    another parent) exits at once. The variable is then removed from this process's
    environment, so the processes it starts are not taken for workers. Anywhere else (the
    sweep itself, a process without the variable, a system other than Linux) nothing happens.

    Notes
    -----
    Linux sends the signal when the *thread* that forked the process ends; distributed forks
    each worker from a thread of its own that lives as long as that worker.
    """
    owner = os.environ.get(SWEEP_PID_ENV, "")
    if not owner.isdigit() or int(owner) == os.getpid() or not sys.platform.startswith("linux"):
        return
    owner = int(owner)
    del os.environ[SWEEP_PID_ENV]
    if os.getppid() != owner:
        if _ended(owner):
            os._exit(1)  # the sweep ended while this worker was starting: nothing would use it
        return
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # no prctl: distributed's own watch of the parent remains
        return
    if os.getppid() != owner:  # the sweep ended before the signal was set
        os._exit(1)


# armed on import, before Warp and Dask load: a worker of `rodwarp sweep` imports this module
# with its parent's main module, about a second before distributed's own watch of its parent
# starts (many seconds when many workers start on few cores)
_die_with_sweep()


def dask_setup(worker=None) -> None:
    """Dask's preload hook, run in each worker of a sweep's local cluster as it starts
    (:func:`_sweep_cluster` preloads this module): :func:`_die_with_sweep` for a worker that
    did not import this module itself (one forked from a process that had)."""
    _die_with_sweep()

from rodwarp.experiments._protocol import ProtocolParams  # noqa: E402 (after _die_with_sweep)
from rodwarp.rodset.files import read_csv_rows, write_json, write_text  # noqa: E402
from rodwarp.validation import check_ranges  # noqa: E402

#: parameters that define a point (besides the ProtocolParams overrides)
GRID_KEYS = ("alpha", "freq", "gravity", "static_load", "seed")
FIXED_KEYS = ("amplitude", "entangle_duration", "duration")
#: result columns, after the parameter columns
RESULT_KEYS = ("a_over_g", "F_tilde", "n_rods", "largest_cluster_fraction", "height_kept", "persistence",
               "rods_left", "contacts_per_rod", "cv_e", "mean_e", "std_e", "stable", "test_duration_s",
               "cycles_tested", "height_kept_landed", "cluster_landed", "persistence_landed", "stable_landed",
               "max_penetration_over_d",
               "device", "wall_s", "entangled_from", "worker", "status")


def _grid_owned(key: str, option: str, field_name: str, example: str) -> str:
    return (f"{key} is set by the sweep itself, one value of its grid per point: give the sweep's {option} "
            f"(SweepSpec.{field_name}), e.g. {option} {example}")


def _fixed_owned(key: str) -> str:
    option = "--" + key.replace("_", "-")
    return f"{key} is set by the sweep itself, the same for every point: give the sweep's {option} (SweepSpec.{key})"


#: a sweep starts each point from a random packing of the point's alpha and seed
_RANDOM_PACKING = ("a sweep always starts each point from a random packing (of the point's alpha and seed), never "
                   "from a rod set")
_INPUT_ONLY = (f"it describes an --initial rod set and {_RANDOM_PACKING}; drop it (`rodwarp simulate --initial "
               f"FILE` runs one rod set)")

#: simulate options (``rodwarp simulate`` option names with underscores, ProtocolParams fields
#: or the command's own) that a sweep owns or that mean nothing in one, given as an override
#: (``--set KEY=VALUE``, ``SweepSpec.overrides``): why, and what to do instead
SWEEP_OWNED = {
    "alpha": _grid_owned("alpha", "--alpha", "alphas", "25,50,100"),
    "freq": _grid_owned("freq", "--freq", "freqs", "1,10"),
    "gravity": _grid_owned("gravity", "--gravity", "gravities", "0.5,10"),
    "static_load": _grid_owned("static_load", "--static-load", "static_loads", "0,1"),
    "seed": "seed is set by the sweep itself: --seeds N runs seeds 0 to N-1 at every point (SweepSpec.seeds)",
    **{k: _fixed_owned(k) for k in FIXED_KEYS},
    "device": "device is set by the sweep itself: give the sweep's --device (SweepSpec.device)",
    "initial": f"{_RANDOM_PACKING}; to start from a rod set of your own, run `rodwarp simulate --initial FILE` "
               f"for each point",
    **{k: _INPUT_ONLY for k in ("initial_diameter", "diameter", "units", "entangle")},
    "out": "a sweep writes each point into its own folder under the sweep's --out (points/<id>/); give --out "
           "to the sweep",
    "resume": "a sweep resumes by itself: run the same `rodwarp sweep` command again (finished points are "
              "skipped, an interrupted point goes on from its checkpoint)",
    "overwrite": "use the sweep's own --overwrite (it replaces the whole sweep folder)",
    "quiet": "use the sweep's own --quiet",
    "entangled_from": "a sweep shares the entangled packing of points that differ only in --freq by itself "
                      "(--share-entangling, the default); a packing of another run cannot be given to a sweep",
}


def _protocol_range(name: str):
    """The :class:`~rodwarp.validation.Range` of the :class:`ProtocolParams` field ``name``."""
    return ProtocolParams.__dataclass_fields__[name].metadata.get("range")


def _grid(*values: float, help: str, of: str | None = None, flag: str | None = None):
    """A :class:`SweepSpec` list field: its default values, its ``rodwarp sweep --help`` line, and
    the range of every item (that of the :class:`ProtocolParams` field ``of``, stated there once)."""
    import dataclasses

    meta = {"help": help}
    if of is not None:
        meta.update(range=dataclasses.replace(_protocol_range(of), each=True), flag=flag or f"--{of.replace('_', '-')}")
    return field(default_factory=lambda: list(values), metadata=meta)


def _as_protocol(name: str, help: str):
    """A :class:`SweepSpec` field whose default and range are the :class:`ProtocolParams` ones
    (stated once)."""
    return field(default=ProtocolParams.__dataclass_fields__[name].default,
                 metadata={"help": help, "range": _protocol_range(name)})


@dataclass(frozen=True)
class SweepSpec:
    """A grid of experiments: every combination of alphas x freqs x gravities x static loads x seeds.

    ``overrides`` sets any other :class:`~rodwarp.experiments.ProtocolParams` field (for example
    ``n_rods``, ``save_every``, ``dt``) for every point; ``analyze`` sets
    :class:`~rodwarp.analysis.AnalyzeOptions` fields (figures are always off in a sweep).
    ``device`` is ``auto`` (a worker with a GPU uses it, the others the CPU), ``cpu`` or ``cuda``.
    The fields' defaults and help texts are those of ``rodwarp sweep``.
    """

    alphas: list = _grid(25.0, 50.0, 100.0, 200.0, 300.0, help="Aspect ratios, comma-separated.", of="alpha")
    freqs: list = _grid(1.0, 10.0, 100.0, help="Stability-test floor frequencies (Hz), comma-separated.", of="freq")
    gravities: list = _grid(0.5, help="Gravitational accelerations (m/s^2), comma-separated.", of="gravity")
    static_loads: list = _grid(0.0, help="Static loads F~, comma-separated.", of="static_load")
    seeds: list = _grid(0, help="Seeds per point (0 .. N-1).", of="seed", flag="seeds")
    entangle_duration: float = _as_protocol("entangle_duration", "Entangling duration (s).")
    duration: float = _as_protocol("duration", "Stability-test duration (s).")
    amplitude: float = _as_protocol("amplitude", "Floor vibration amplitude (m).")
    overrides: dict = field(default_factory=dict)
    analyze: dict = field(default_factory=dict)
    device: str = field(default="auto", metadata={"help": "Warp device of each point (auto: the worker's GPU if any)."})
    share_entangling: bool = field(default=True, metadata={
        "help": "Points that differ only in the test's frequency share one entangled packing: the first runs the "
                "whole protocol, the others start their test from its entangled.npz (the same results, bit for "
                "bit on the CPU, without entangling again)."})

    def validate(self) -> "SweepSpec":
        """Refuse (one line) an empty grid, unknown or sweep-owned overrides, unknown analyze
        options; return the spec with every grid a list (a single number given for one) and
        the seeds integers (the spec itself is frozen)."""
        from rodwarp.analysis import AnalyzeOptions

        grid = {}
        for name in ("alphas", "freqs", "gravities", "static_loads", "seeds"):
            v = getattr(self, name)
            grid[name] = [v] if isinstance(v, (int, float)) else list(v)
            if not grid[name]:
                raise RodwarpError(f"sweep: '{name}' is empty; give at least one value")
        grid["seeds"] = [int(s) for s in grid["seeds"]]
        check_ranges(replace(self, **grid))  # each grid item and value within its ProtocolParams range
        own = sorted(set(self.overrides) & set(SWEEP_OWNED))
        for k, v in self.overrides.items():  # --save-every is an override of its own option
            rng = _protocol_range(k) if k in ProtocolParams.__dataclass_fields__ and k not in SWEEP_OWNED else None
            if rng is not None and v is not None:
                rng.check("--save-every" if k == "save_every" else f"--set {k}", v)
        if own:
            raise RodwarpError(f"sweep: override {own[0]}: {SWEEP_OWNED[own[0]]}")
        known = {f.name for f in fields(ProtocolParams)}
        bad = sorted(set(self.overrides) - known)
        if bad:
            raise RodwarpError(f"sweep: unknown simulate parameter(s) {', '.join(bad)}")
        aknown = {f.name for f in fields(AnalyzeOptions)}
        bad = sorted(set(self.analyze) - aknown)
        if bad:
            raise RodwarpError(f"sweep: unknown analyze option(s) {', '.join(bad)}")
        return replace(self, **grid)

    def to_dict(self) -> dict:
        return asdict(self)


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def point_id(point: dict) -> str:
    """Directory name of a point, from its grid parameters (stable across runs)."""
    return (f"alpha{_fmt(float(point['alpha']))}_freq{_fmt(float(point['freq']))}"
            f"_g{_fmt(float(point['gravity']))}_F{_fmt(float(point['static_load']))}_seed{int(point['seed'])}")


def points(spec: SweepSpec) -> list[dict]:
    """Every point of the grid (largest alpha first: the longest runs start first).

    Each point is a flat dict of its parameters (grid values, amplitude, durations, the
    overrides, ``device``) plus ``id`` and the analyze options under ``_analyze``.
    """
    spec = spec.validate()
    out = []
    for a in sorted({float(x) for x in spec.alphas}, reverse=True):
        for f in sorted({float(x) for x in spec.freqs}):
            for g in sorted({float(x) for x in spec.gravities}):
                for s in sorted({float(x) for x in spec.static_loads}):
                    for seed in sorted(set(spec.seeds)):
                        p = {"alpha": a, "freq": f, "gravity": g, "static_load": s, "seed": int(seed),
                             "amplitude": float(spec.amplitude),
                             "entangle_duration": float(spec.entangle_duration),
                             "duration": float(spec.duration), **dict(spec.overrides),
                             "device": spec.device}
                        p["id"] = point_id(p)
                        p["_analyze"] = dict(spec.analyze)
                        out.append(p)
    return out


def entangling_groups(pts: list[dict]) -> list[list[dict]]:
    """The points grouped by their entangled packing: every parameter but the test's frequency
    (the amplitude and durations are the sweep's own, common to all points).

    Groups come in the order of their first point (largest alpha first); within a group the
    lowest frequency comes first: it runs the whole protocol (its test is the cheapest, at
    least 40 steps per drive period), and the others start their test from its entangled
    packing (:func:`run_point` with ``entangled_from``).
    """
    groups: dict = {}
    for p in pts:
        key = tuple(sorted((k, repr(v)) for k, v in p.items() if k not in ("id", "freq") and not k.startswith("_")))
        groups.setdefault(key, []).append(p)
    return [sorted(g, key=lambda q: float(q["freq"])) for g in groups.values()]


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _one_line(e: BaseException) -> str:
    msg = str(e).strip().splitlines()
    msg = msg[0] if msg else ""
    return f"{type(e).__name__}: {msg}" if not isinstance(e, RodwarpError) else f"error: {msg}"


def _empty_row(point: dict) -> dict:
    """A results row of ``point``: its parameters, every result column empty."""
    row = {k: v for k, v in point.items() if not k.startswith("_")}
    row.update({k: None for k in RESULT_KEYS})
    return row


def _donor_ready(donor_dir, donor_row) -> bool:
    """The donor's entangled packing can be used: its run succeeded (when its row is known)
    and its folder holds ``entangled.npz``."""
    from rodwarp.experiments._protocol import ENTANGLED

    if donor_dir is None:
        return False
    if donor_row is not None and donor_row.get("status") != "ok":
        return False
    return (Path(donor_dir) / ENTANGLED).is_file()


def run_point(point: dict, outdir: str, entangled_from: str | None = None, donor_row: dict | None = None) -> dict:
    """Run one point: simulate into ``outdir`` then analyze its final packing (no figures).

    Never raises: a failure is returned as a row whose ``status`` is the error's one-line
    message. The row holds every parameter of the point and the results (see ``RESULT_KEYS``).
    A checkpoint left in ``outdir`` by an interrupted run is resumed.

    ``entangled_from`` is the folder of a point of the same entangled packing (another test
    frequency; ``donor_row`` its result row, which a Dask sweep passes so that this point runs
    only after it): this point's test then starts from that run's ``entangled.npz``. When the
    donor failed or holds none, the point runs its own entangling; the row's
    ``entangled_from`` says which (the donor's folder name, or empty).
    """
    t0 = time.perf_counter()
    row = _empty_row(point)
    row["worker"] = _worker_name()
    row["F_tilde"] = point.get("static_load")
    try:
        from rodwarp.analysis import analyze
        from rodwarp.experiments._protocol import run_protocol

        params = _point_params(point)
        row["a_over_g"] = params.a_over_g
        out = Path(outdir)
        resume = (out / "checkpoints").is_dir() and any((out / "checkpoints").glob("ckpt_*.npz")) \
            and (out / "initial.npz").exists()
        donor = entangled_from if not resume and _donor_ready(entangled_from, donor_row) else None
        try:
            # the point's folder belongs to the sweep: a fresh run replaces whatever it holds
            summary = run_protocol(params, out, progress=False, resume=resume, overwrite=not resume,
                                   entangled_from=donor)
        except RodwarpError:
            if not (resume or donor):
                raise
            # a checkpoint of other parameters, or of a finished run; or a donor that does not fit
            summary = run_protocol(params, out, progress=False, resume=False, overwrite=True)
        rec = summary.get("entangled_from")
        row["entangled_from"] = Path(rec["run"]).name if rec else ""
        opts = _point_analysis(point)
        dev = summary.get("device", "cpu")
        if opts.device == "cpu" and "device" not in point.get("_analyze", {}) and str(dev).startswith("cuda"):
            opts = replace(opts, device=dev)
        a = analyze(out, out / "analysis", opts)
        row.update({**summary_columns(summary),
                    "cv_e": a.get("cv_e"), "mean_e": a.get("mean_e"), "std_e": a.get("std_e"), "status": "ok"})
    except BaseException as e:  # noqa: BLE001 - a failed point is recorded, never raised
        if isinstance(e, (KeyboardInterrupt, SystemExit)):
            raise
        row["status"] = _one_line(e)
        if os.environ.get("RODWARP_DEBUG"):
            row["status"] += " | " + traceback.format_exc().replace("\n", " ")
    row["wall_s"] = time.perf_counter() - t0
    return row


def summary_columns(summary: dict) -> dict:
    """results.csv's columns that a finished run's summary.json gives (all but the analysis's
    cv_e, mean_e, std_e and the bookkeeping)."""
    return {"n_rods": summary["n_rods"], "a_over_g": summary["a_over_g"],
            "largest_cluster_fraction": summary["largest_cluster_fraction"],
            "height_kept": summary["height_kept"], "persistence": summary["persistence"],
            "rods_left": summary["rods_left"],
            "contacts_per_rod": summary["contacts_per_rod"], "stable": bool(summary["stable"]),
            "max_penetration_over_d": summary.get("max_penetration_over_d"),
            "device": summary.get("device", "cpu"), **_landed_columns(summary)}


def _landed_columns(summary: dict) -> dict:
    """results.csv's test length and landed measures (docs/verdict.md, "The landed phase") from a
    run's summary: empty where the test was not sampled finely enough to find the landing."""
    dur = float(summary["parameters"]["duration"])
    landed = summary.get("landed") or {}
    stable = landed.get("stable")
    return {"test_duration_s": dur, "cycles_tested": dur * float(summary["freq"]),
            "height_kept_landed": landed.get("height_kept"),
            "cluster_landed": landed.get("largest_cluster_fraction"),
            "persistence_landed": landed.get("persistence"),
            "stable_landed": None if stable is None else bool(stable)}


def check_points(pts: list[dict], *, local: bool) -> float:
    """Validate every point's simulate parameters and analyze options before any cluster
    starts; the first invalid point is refused with its id and the reason (one line).

    Parameters
    ----------
    pts : list of dict
        The points (:func:`points`).
    local : bool
        The points run on this machine, so the device must exist here too.

    Returns
    -------
    float
        The largest point's memory estimate (bytes): what one worker running it needs.
    """
    need = 0.0
    for p in pts:
        try:
            need = max(need, _validate_point(p))
        except RodwarpError as e:
            bad = sum(1 for q in pts if _invalid(q))
            raise RodwarpError(f"sweep point {p['id']} is invalid ({e}); invalid points: {bad} of {len(pts)}; "
                               f"no point was run: fix the sweep's values") from None
    if local and pts:
        from rodwarp import _warp

        _warp.resolve_device(pts[0]["device"])
    return need


def usable_cores() -> int:
    """Cores this process may run on: its CPU affinity (``os.cpu_count()`` where that is unknown)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return os.cpu_count() or 1


def worker_limit(point_bytes: float) -> tuple[int, str]:
    """The most worker processes a local cluster may have on this machine, and what sets it.

    One worker runs one point on one core (Warp's CPU kernels use one thread), so a worker per
    usable core (:func:`usable_cores`) is the most that run at once; more only share the cores,
    and each worker costs memory and about a second of start-up. Each worker also holds its
    point's memory (the simulate estimate of :func:`check_points`), so no more than the
    available memory holds (:func:`rodwarp.validation.available_memory`).

    Parameters
    ----------
    point_bytes : float
        Memory one point needs (bytes): the largest point's estimate.

    Returns
    -------
    limit : int
        The most workers (at least 1: a point that does not fit alone is refused by its own check).
    reason : str
        What sets it, for a refusal ("this machine's 2 cores", "the 3.2 GB of memory available ...").
    """
    from rodwarp.validation import available_memory, human_bytes

    cores = usable_cores()
    have = available_memory()
    by_memory = int(have // point_bytes) if point_bytes > 0 and math.isfinite(have) else cores
    if by_memory < cores:
        return max(1, by_memory), (f"what the {human_bytes(have)} of memory available holds (each worker needs "
                                   f"about {human_bytes(point_bytes)} for the sweep's largest point)")
    return cores, f"this machine's {cores} cores (each worker runs one point on one core)"


def local_workers(workers: int | None, point_bytes: float) -> int:
    """The worker processes of a sweep's local cluster: ``workers``, or :func:`worker_limit`'s
    limit when None; a count below 1 or above the limit is refused (one line naming the fix)."""
    from rodwarp.validation import integer

    limit, reason = worker_limit(point_bytes)
    if workers is None:
        return limit
    workers = integer("--workers", workers, ge=1)
    if workers > limit:
        raise RodwarpError(f"--workers {workers} is more than {reason}; use --workers {limit} or fewer "
                           f"(default: as many as the cores and memory allow)")
    return workers


def _point_params(point: dict) -> ProtocolParams:
    """The simulate parameters of a point (its id and ``_``-keys left out; a box read back as a list)."""
    kw = {k: v for k, v in point.items() if k != "id" and not k.startswith("_")}
    if "box" in kw and isinstance(kw["box"], list):
        kw["box"] = tuple(kw["box"])
    return ProtocolParams(**kw)


def _point_analysis(point: dict):
    """The analyze options of a point (never figures: a sweep draws its own)."""
    from rodwarp.analysis import AnalyzeOptions

    return AnalyzeOptions(**{**point.get("_analyze", {}), "figures": False})


def _validate_point(point: dict) -> float:
    """Validate a point's parameters and analyze options; its memory estimate (bytes)."""
    from rodwarp.experiments._checks import BYTES_PER_VERTEX
    from rodwarp.validation import BASE_BYTES

    checked = _point_params(point).validate()
    _point_analysis(point).validate()
    return BASE_BYTES + BYTES_PER_VERTEX * checked.n_vertices


def _invalid(p: dict) -> bool:
    try:
        _validate_point(p)
    except RodwarpError:
        return True
    return False


def _submit(client, spec: SweepSpec, pts: list[dict], todo: list[dict], out: Path) -> dict:
    """Submit every point of ``todo`` to ``client``; ``{future: point}``.

    With ``spec.share_entangling`` each group of :func:`entangling_groups` is submitted in
    turn, its donor first and the others after it: an unfinished donor's future is an
    argument of the others, so Dask runs them once it is done (and in parallel); a donor
    finished in an earlier sweep is used directly. Each task's Dask priority is its place in
    that order (submissions within ``fifo_timeout`` of each other would otherwise tie, and
    Dask broke the tie its own way: a one-worker sweep ran alpha 50 before alpha 200), so a
    free worker takes the first ready point: largest alpha first, a group's other points
    before the next groups' donors.
    """
    folder = lambda p: str((out / "points" / p["id"]).resolve())  # noqa: E731
    key = lambda p: f"rodwarp-{p['id']}-{time.time_ns()}"  # noqa: E731
    pending = {p["id"] for p in todo}
    futs = {}
    groups = entangling_groups(pts) if spec.share_entangling else [[p] for p in pts]
    rank = len(pts)
    for group in groups:
        donor, donor_fut = group[0], None
        for p in group:
            if p["id"] not in pending:
                continue
            rank -= 1
            if p is donor or len(group) == 1:
                fut = client.submit(run_point, p, folder(p), pure=False, key=key(p), priority=rank)
                donor_fut = fut
            else:
                fut = client.submit(run_point, p, folder(p), folder(donor), donor_fut, pure=False, key=key(p),
                                    priority=rank)
            futs[fut] = p
    return futs


# --------------------------------------------------------------------------------------- CSV


#: columns every results.csv has: run_sweep keys its rows by ``id`` and skips the ``ok`` ones
RESULTS_REQUIRED = ("id", "status")

#: what every refusal of a results.csv says to do (the sweep writes the file whole, atomically)
_RESULTS_FIX = ("results.csv holds only what `rodwarp sweep` writes: restore it, or rerun the sweep into a "
                "clean folder")


def read_results(path, required=RESULTS_REQUIRED) -> list[dict]:
    """Rows of a results.csv as dicts of strings (empty list when it does not exist or is empty).

    Parameters
    ----------
    path : path-like
        The CSV.
    required : sequence of str
        Columns its header must name (default :data:`RESULTS_REQUIRED`).

    Returns
    -------
    list of dict
        One dict per data row, keyed by the header's names; a short row's missing cells are None.

    Raises
    ------
    RodwarpError
        One line when ``path`` is a folder, is not UTF-8 text (a binary or other-encoding
        file: Python's UnicodeDecodeError would be an internal error) or holds NUL bytes, is
        not CSV, lacks a required column, or has a row with more cells than its header (its
        values would be read under the wrong names).
    """
    path = Path(path)
    if not path.exists():
        return []
    header, rows = read_csv_rows(path, _RESULTS_FIX)
    if not header:
        return []
    missing = [c for c in required if c not in header]
    if missing:
        shown = ", ".join(repr(h) for h in header[:6]) + (", ..." if len(header) > 6 else "")
        raise RodwarpError(f"{path} lacks the column(s) {', '.join(missing)} (its header: {shown}); "
                           f"{_RESULTS_FIX}")
    for i, r in enumerate(rows, 1):
        if None in r:  # csv.DictReader files a long row's surplus cells under None
            raise RodwarpError(f"{path}: data row {i} (id {r.get('id') or ''!r}) has {len(r[None])} more cell(s) "
                               f"than the header's {len(header)} columns; {_RESULTS_FIX}")
    return rows


def _columns(rows: list[dict]) -> list[str]:
    first = ["id", *GRID_KEYS, *FIXED_KEYS]
    extra = []
    for r in rows:
        for k in r:
            if k not in first and k not in RESULT_KEYS and k not in extra:
                extra.append(k)
    return first + extra + list(RESULT_KEYS)


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else repr(v)
    if isinstance(v, (list, tuple)):
        return " ".join(_cell(x) for x in v)
    return str(v)


def write_results(path, rows: list[dict]) -> None:
    """Write the whole CSV to a temporary file and rename it over ``path`` (crash-safe)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=_columns(rows), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: _cell(v) for k, v in r.items()})
    write_text(path, buf.getvalue())


def _same_point(row: dict, point: dict) -> bool:
    """A CSV row (strings) was produced by this point's parameters."""
    for k, v in point.items():
        if k.startswith("_") or k in ("id", "device"):
            continue
        s = row.get(k)
        if s is None:
            return False
        if _cell(v) == s:
            continue
        try:
            if math.isclose(float(s), float(v), rel_tol=1e-9):
                continue
        except (TypeError, ValueError):
            pass
        return False
    return True


# ------------------------------------------------------------------------------------- sweep


def run_sweep(spec: SweepSpec, out, scheduler: str | None = None, workers: int | None = None,
              progress: bool = True, overwrite: bool = False) -> Path:
    """Run every unfinished point of ``spec`` on Dask and record the results under ``out``.

    Parameters
    ----------
    spec : SweepSpec
        The grid.
    out : path-like
        Sweep directory (created). ``out/results.csv`` gets one row per point, rewritten
        atomically as each point completes; ``out/points/<id>/`` holds each point's outputs.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://HOST:8786``). Without it a
        ``LocalCluster`` of ``workers`` single-threaded worker processes is started on
        127.0.0.1 with no dashboard, and closed at the end.
    workers : int, optional
        Worker processes of the local cluster: at most one per usable core and no more than
        memory holds (:func:`worker_limit`; more is refused), and that many by default.
        Ignored with ``scheduler``. The workers end with this process, however it ends
        (:func:`_sweep_cluster`).
    progress : bool
        Show a progress bar (points done of total, time remaining).
    overwrite : bool
        Replace whatever run ``out`` holds. Without it a sweep adds its points to the folder's
        sweep of the same :func:`protocol` (finished points are kept, not rerun) and refuses a
        folder of another protocol or of another command, naming what differs.

    Returns
    -------
    Path
        ``out/results.csv``.
    """
    from distributed import as_completed

    from rodwarp._util import progress_bar, versions
    from rodwarp.experiments._checks import check_scheduler
    from rodwarp.rodset import rundir
    from rodwarp.validation import output_location

    spec = spec.validate()
    pts = points(spec)
    point_bytes = check_points(pts, local=not scheduler)
    if not scheduler:
        workers = local_workers(workers, point_bytes)
    out = Path(out)
    output_location(out, "--out")
    # the folder is checked before the scheduler is contacted: a refusal costs nothing
    legacy = _legacy_protocol(out)
    rundir.check(out, "sweep", protocol(spec), SWEEP_OUTPUTS, overwrite=overwrite, append=True,
                 legacy=legacy)
    if scheduler:
        scheduler = check_scheduler(scheduler)
    # a sweep adds points to the folder's sweep of the same protocol and is refused for any
    # other (results of two protocols never share a results.csv or a phase diagram)
    run = rundir.claim(out, "sweep", protocol(spec), SWEEP_OUTPUTS, overwrite=overwrite, append=True,
                       legacy=legacy)
    (out / "points").mkdir(parents=True, exist_ok=True)
    csv_path = out / "results.csv"
    old = {r.get("id"): r for r in read_results(csv_path)}
    done, todo = [], []
    for p in pts:
        r = old.get(p["id"])
        if r is not None and r.get("status") == "ok" and _same_point(r, p):
            done.append(p["id"])
        else:
            todo.append(p)
    # rows in grid order: finished rows kept as read, the others filled in as they complete
    rows: dict = {pid: old[pid] for pid in done}
    extra = {k: v for k, v in old.items() if k not in {p["id"] for p in pts}}  # rows of other grids: kept
    order = [p["id"] for p in pts]

    def flush():
        ordered = [rows[i] for i in order if i in rows] + list(extra.values())
        if ordered:
            write_results(csv_path, ordered)

    meta = {"spec": spec.to_dict(), "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
            "scheduler": scheduler or LOCAL_CLUSTER,
            "workers": None if scheduler else workers,
            "n_points": len(pts), "skipped": len(done), "submitted": len(todo),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "finished": None, "failed": None,
            "versions": versions("dask", "distributed"), "results": "results.csv", "points": "points/"}
    write_json(out / "sweep.json", meta)
    failed = 0
    t0 = time.perf_counter()
    if todo:
        with (contextlib.closing(_connect(scheduler)) if scheduler else _sweep_cluster(workers)) as client:
            futs = _submit(client, spec, pts, todo, out)
            with progress_bar(progress, "points", remaining=True, note=True) as update:
                n_done = len(done)
                update("sweep", n_done, len(pts))
                for fut in as_completed(list(futs)):
                    p = futs[fut]
                    try:
                        row = fut.result()
                    except Exception as e:  # noqa: BLE001 - worker died (KilledWorker) or similar
                        row = _empty_row(p)
                        row["status"] = _one_line(e)
                    if row.get("status") != "ok":
                        failed += 1
                        meta.setdefault("first_failure", f"{p['id']}: {row.get('status')}")
                    rows[p["id"]] = row
                    flush()
                    n_done += 1
                    update("sweep", n_done, len(pts), note=f"{p['id']}: {row.get('status')}"[:80])
    else:
        flush()
    meta.update({"finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "failed": failed,
                 "wall_s": time.perf_counter() - t0})
    write_json(out / "sweep.json", meta)
    run.complete(n_points=len(pts), failed=failed)
    return csv_path


def _no_nanny_start_failure(record: logging.LogRecord) -> bool:
    """A logging filter: False for asyncio's report of a nanny that failed to start (the
    cluster's start was cut short), True for anything else."""
    exc = record.exc_info[1] if record.exc_info else None
    return not (isinstance(exc, RuntimeError) and str(exc).startswith("Nanny failed to start"))


@contextlib.contextmanager
def _sweep_cluster(n_workers: int):
    """A client of a local cluster of ``n_workers`` workers (:func:`_local_cluster`) whose worker
    processes end with this process; the client and cluster are closed on leaving.

    While the cluster runs, :data:`SWEEP_PID_ENV` names this process to the workers it spawns
    (restarted ones included), and each worker preloads this module: its
    :func:`_die_with_sweep` asks Linux to kill the worker when this process ends, so a
    ``kill -9`` of the sweep leaves no worker behind (distributed's own watch of the parent,
    a pipe read by a thread, starts only once the worker has imported Dask).
    """
    import dask
    import distributed  # noqa: F401 - its config defaults, which the dask.config.set below would drop on exit
    from distributed.deploy.spec import SpecCluster

    before = os.environ.get(SWEEP_PID_ENV)
    os.environ[SWEEP_PID_ENV] = str(os.getpid())
    try:
        preload = [*dask.config.get("distributed.worker.preload", []), __name__]
        others = set(SpecCluster._instances)
        try:
            with dask.config.set({"distributed.worker.preload": preload}):
                cluster, client = _local_cluster(n_workers)
        except BaseException:
            # a start cut short (Ctrl-C) leaves a cluster whose workers are still starting:
            # distributed's exit hook would fail to close it and asyncio would report its
            # nannies' failed starts, each with a traceback; its workers end with this process
            for half_started in set(SpecCluster._instances) - others:
                half_started.shutdown_on_close = False
            logging.getLogger("asyncio").addFilter(_no_nanny_start_failure)
            raise
        try:
            yield client
        finally:
            client.close()
            cluster.close()
    finally:
        if before is None:
            os.environ.pop(SWEEP_PID_ENV, None)
        else:
            os.environ[SWEEP_PID_ENV] = before


#: SweepSpec fields that choose the grid's points or how they are run, not what a point
#: measures: two sweeps that differ only in these may share a folder and a results.csv
_NOT_PROTOCOL = ("alphas", "freqs", "gravities", "static_loads", "seeds", "device", "share_entangling")


def protocol(spec: SweepSpec) -> dict:
    """What every point of a sweep shares (durations, amplitude, overrides, analysis options):
    the parameters a second sweep into the same folder must repeat (:func:`run_sweep`)."""
    return {k: v for k, v in spec.to_dict().items() if k not in _NOT_PROTOCOL}


def _legacy_protocol(out: Path) -> dict | None:
    """The protocol of a sweep written before manifests (its ``sweep.json``), or None."""
    from rodwarp.rodset import rundir

    if not (out / "sweep.json").is_file() or rundir.read_manifest(out) is not None:
        return None
    try:
        spec = json.loads((out / "sweep.json").read_text()).get("spec") or {}
        return protocol(SweepSpec(**{k: v for k, v in spec.items() if k in {f.name for f in fields(SweepSpec)}}))
    except (OSError, ValueError, TypeError, AttributeError):
        return {"unreadable sweep.json": True}
