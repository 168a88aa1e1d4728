"""Parameter sweeps of the rod-packing experiment on Dask, and the entanglement phase diagram.

One point of a sweep is one ``simulate`` run (:func:`rodwarp.protocol.run_protocol`) followed
by ``analyze`` of its final packing, executed as a single task on a ``dask.distributed``
cluster: a :class:`distributed.LocalCluster` of worker processes on this machine (loopback
only, no dashboard) by default, or an existing cluster when a scheduler address is given.

Layout of a sweep directory ``OUT``::

    OUT/sweep.json        the spec, the command, versions, counts
    OUT/results.csv       one row per point (rewritten atomically after every point)
    OUT/points/<id>/      each point's full simulate output, with analyze output in analysis/
    OUT/phase_*.png       figures of :func:`phase_diagram`, OUT/alpha_star.csv

Running the same sweep again skips points whose row has ``status`` ``ok``; a failed point is
recorded with its one-line error and the others go on. Results are plain CSV/JSON files.
"""

from __future__ import annotations

import csv
import io
import math
import os
import socket
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

from rodwarp.rodset.files import write_json, write_text
from rodwarp.errors import RodwarpError

#: parameters that define a point (besides the ProtocolParams overrides)
GRID_KEYS = ("alpha", "freq", "gravity", "static_load", "seed")
FIXED_KEYS = ("amplitude", "entangle_duration", "duration")
#: result columns, after the parameter columns
RESULT_KEYS = ("a_over_g", "F_tilde", "n_rods", "largest_cluster_fraction", "height_kept", "persistence",
               "rods_left", "contacts_per_rod", "cv_e", "mean_e", "std_e", "stable", "max_penetration_over_d",
               "device", "wall_s", "worker", "status")
#: ProtocolParams fields a sweep sets itself (not allowed in ``overrides``)
_OWN = set(GRID_KEYS) | set(FIXED_KEYS) | {"device", "initial"}


@dataclass
class SweepSpec:
    """A grid of experiments: every combination of alphas x freqs x gravities x static loads x seeds.

    ``overrides`` sets any other :class:`~rodwarp.protocol.ProtocolParams` field (for example
    ``n_rods``, ``save_every``, ``dt``) for every point; ``analyze`` sets
    :class:`~rodwarp.analyze.AnalyzeOptions` fields (figures are always off in a sweep).
    ``device`` is ``auto`` (a worker with a GPU uses it, the others the CPU), ``cpu`` or ``cuda``.
    """

    alphas: list = field(default_factory=lambda: [25.0, 50.0, 100.0, 200.0, 300.0])
    freqs: list = field(default_factory=lambda: [1.0, 10.0, 100.0])
    gravities: list = field(default_factory=lambda: [0.5])
    static_loads: list = field(default_factory=lambda: [0.0])
    seeds: list = field(default_factory=lambda: [0])
    entangle_duration: float = 5.0
    duration: float = 5.0
    amplitude: float = 0.001
    overrides: dict = field(default_factory=dict)
    analyze: dict = field(default_factory=dict)
    device: str = "auto"

    def validate(self) -> None:
        from rodwarp.analysis import AnalyzeOptions
        from rodwarp.protocol import ProtocolParams

        for name in ("alphas", "freqs", "gravities", "static_loads", "seeds"):
            v = getattr(self, name)
            if isinstance(v, (int, float)):
                setattr(self, name, [v])
            if not getattr(self, name):
                raise RodwarpError(f"sweep: '{name}' is empty; give at least one value")
        self.seeds = [int(s) for s in self.seeds]
        known = {f.name for f in fields(ProtocolParams)}
        bad = sorted(set(self.overrides) - known)
        if bad:
            raise RodwarpError(f"sweep: unknown simulate parameter(s) {', '.join(bad)}")
        own = sorted(set(self.overrides) & _OWN)
        if own:
            raise RodwarpError(f"sweep: {', '.join(own)} is set by the sweep itself, not by overrides")
        aknown = {f.name for f in fields(AnalyzeOptions)}
        bad = sorted(set(self.analyze) - aknown)
        if bad:
            raise RodwarpError(f"sweep: unknown analyze option(s) {', '.join(bad)}")

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
    spec.validate()
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


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _one_line(e: BaseException) -> str:
    msg = str(e).strip().splitlines()
    msg = msg[0] if msg else ""
    return f"{type(e).__name__}: {msg}" if not isinstance(e, RodwarpError) else f"error: {msg}"


def run_point(point: dict, outdir: str) -> dict:
    """Run one point: simulate into ``outdir`` then analyze its final packing (no figures).

    Never raises: a failure is returned as a row whose ``status`` is the error's one-line
    message. The row holds every parameter of the point and the results (see ``RESULT_KEYS``).
    A checkpoint left in ``outdir`` by an interrupted run is resumed.
    """
    t0 = time.perf_counter()
    row = {k: v for k, v in point.items() if not k.startswith("_")}
    row.update({k: None for k in RESULT_KEYS})
    row["worker"] = _worker_name()
    row["F_tilde"] = point.get("static_load")
    try:
        from rodwarp.analysis import AnalyzeOptions, analyze
        from rodwarp.protocol import ProtocolParams, run_protocol

        kw = {k: v for k, v in point.items() if k not in ("id",) and not k.startswith("_")}
        if "box" in kw and isinstance(kw["box"], list):
            kw["box"] = tuple(kw["box"])
        params = ProtocolParams(**kw)
        row["a_over_g"] = params.a_over_g
        out = Path(outdir)
        resume = (out / "checkpoints").is_dir() and any((out / "checkpoints").glob("ckpt_*.npz")) \
            and (out / "initial.npz").exists()
        try:
            # the point's folder belongs to the sweep: a fresh run replaces whatever it holds
            summary = run_protocol(params, out, progress=False, resume=resume, overwrite=not resume)
        except RodwarpError:
            if not resume:
                raise
            # a checkpoint of other parameters, or of a finished run
            summary = run_protocol(params, out, progress=False, resume=False, overwrite=True)
        opts = AnalyzeOptions(**{**point.get("_analyze", {}), "figures": False})
        dev = summary.get("device", "cpu")
        if opts.device == "cpu" and "device" not in point.get("_analyze", {}) and str(dev).startswith("cuda"):
            opts.device = dev
        a = analyze(out, out / "analysis", opts)
        row.update({
            "n_rods": summary["n_rods"], "a_over_g": summary["a_over_g"],
            "largest_cluster_fraction": summary["largest_cluster_fraction"],
            "height_kept": summary["height_kept"], "persistence": summary["persistence"],
            "rods_left": summary["rods_left"],
            "contacts_per_rod": summary["contacts_per_rod"], "stable": bool(summary["stable"]),
            "max_penetration_over_d": summary.get("max_penetration_over_d"), "device": dev,
            "cv_e": a.get("cv_e"), "mean_e": a.get("mean_e"), "std_e": a.get("std_e"),
            "status": "ok",
        })
    except BaseException as e:  # noqa: BLE001 - a failed point is recorded, never raised
        if isinstance(e, (KeyboardInterrupt, SystemExit)):
            raise
        row["status"] = _one_line(e)
        if os.environ.get("RODWARP_DEBUG"):
            row["status"] += " | " + traceback.format_exc().replace("\n", " ")
    row["wall_s"] = time.perf_counter() - t0
    return row


def check_points(pts: list[dict], *, local: bool) -> None:
    """Validate every point's simulate parameters and analyze options before any cluster
    starts; the first invalid point is refused with its id and the reason (one line).

    ``local``: the points run on this machine, so the device must exist here too.
    """
    from rodwarp.analysis import AnalyzeOptions
    from rodwarp.protocol import ProtocolParams

    for p in pts:
        kw = {k: v for k, v in p.items() if k != "id" and not k.startswith("_")}
        if "box" in kw and isinstance(kw["box"], list):
            kw["box"] = tuple(kw["box"])
        try:
            ProtocolParams(**kw).validate()
            AnalyzeOptions(**{**p.get("_analyze", {}), "figures": False}).validate()
        except RodwarpError as e:
            bad = sum(1 for q in pts if _invalid(q))
            raise RodwarpError(f"sweep point {p['id']} is invalid ({e}); invalid points: {bad} of {len(pts)}; "
                               f"no point was run: fix the sweep's values") from None
    if local and pts:
        from rodwarp import _warp

        _warp.resolve_device(pts[0]["device"])


def _invalid(p: dict) -> bool:
    from rodwarp.analysis import AnalyzeOptions
    from rodwarp.protocol import ProtocolParams

    kw = {k: v for k, v in p.items() if k != "id" and not k.startswith("_")}
    if "box" in kw and isinstance(kw["box"], list):
        kw["box"] = tuple(kw["box"])
    try:
        ProtocolParams(**kw).validate()
        AnalyzeOptions(**{**p.get("_analyze", {}), "figures": False}).validate()
    except RodwarpError:
        return True
    return False


def _stop_http(dask_worker=None, dask_scheduler=None) -> None:
    node = dask_worker or dask_scheduler
    server = getattr(node, "http_server", None)
    if server is not None:
        server.stop()


def _connect(address: str, timeout: float = 5.0):
    """A Client of the scheduler at ``address``, or a one-line error within ``timeout`` s.

    The TCP check of :func:`rodwarp.validation.check_scheduler` comes first; this catches a
    port that accepts connections but does not speak Dask (a proxy, another service)."""
    from distributed import Client

    try:
        return Client(address, timeout=f"{timeout:g}s")
    except Exception as e:  # noqa: BLE001 - distributed raises OSError, TimeoutError, even MemoryError here
        raise RodwarpError(f"--scheduler {address}: no Dask scheduler answers there within {timeout:g} s "
                           f"({type(e).__name__}); start one with `dask scheduler` or check the address") from None


def _local_cluster(n_workers: int):
    """A LocalCluster of single-threaded worker processes on 127.0.0.1 with no HTTP server.

    distributed always starts an HTTP server on the scheduler (port 8787: /metrics, /health,
    /info even without a dashboard) and on each worker; a sweep on this machine needs none,
    so no routes are mounted and the servers are stopped once the cluster is up.
    """
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set({"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []}):
        # a random loopback port (not 8787, which another cluster may hold) for the server
        # that is stopped below
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, worker_dashboard_address=None,
                               scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"})
    client = Client(cluster)
    _stop_http(dask_scheduler=cluster.scheduler)
    client.run(_stop_http)
    return cluster, client


# --------------------------------------------------------------------------------------- CSV


def read_results(path) -> list[dict]:
    """Rows of a results.csv as dicts of strings (empty list when it does not exist)."""
    path = Path(path)
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


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


def _versions() -> dict:
    import platform

    import rodwarp

    v = {"rodwarp": rodwarp.__version__, "python": platform.python_version(), "platform": platform.platform()}
    for mod in ("dask", "distributed", "warp", "numpy"):
        try:
            m = __import__(mod)
            v[mod] = getattr(m, "__version__", None) or getattr(getattr(m, "config", None), "version", None)
        except Exception:  # noqa: BLE001
            v[mod] = None
    return v


def run_sweep(spec: SweepSpec, out, scheduler: str | None = None, workers: int | None = None,
              progress: bool = True) -> Path:
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
        Worker processes of the local cluster (default: the number of cores). Ignored with
        ``scheduler``.
    progress : bool
        Show a progress bar (points done of total, time remaining).

    Returns
    -------
    Path
        ``out/results.csv``.
    """
    from distributed import as_completed

    from rodwarp.validation import check_scheduler, output_location

    spec.validate()
    pts = points(spec)
    check_points(pts, local=not scheduler)
    out = Path(out)
    output_location(out, "--out")
    if scheduler:
        scheduler = check_scheduler(scheduler)
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
            "scheduler": scheduler or "LocalCluster(127.0.0.1)",
            "workers": None if scheduler else (workers or os.cpu_count()),
            "n_points": len(pts), "skipped": len(done), "submitted": len(todo),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "finished": None, "failed": None,
            "versions": _versions(), "results": "results.csv", "points": "points/"}
    write_json(out / "sweep.json", meta)
    failed = 0
    t0 = time.perf_counter()
    if todo:
        cluster = None
        if scheduler:
            client = _connect(scheduler)
        else:
            cluster, client = _local_cluster(workers or os.cpu_count() or 1)
        bar = None
        try:
            futs = {}
            for p in todo:
                fut = client.submit(run_point, p, str((out / "points" / p["id"]).resolve()), pure=False,
                                    key=f"rodwarp-{p['id']}-{time.time_ns()}")
                futs[fut] = p
            if progress:
                from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                           TimeElapsedColumn, TimeRemainingColumn)

                bar = Progress(TextColumn("sweep"), BarColumn(), MofNCompleteColumn(), TextColumn("points"),
                               TimeElapsedColumn(), TextColumn("remaining"), TimeRemainingColumn(),
                               TextColumn("{task.fields[last]}"), transient=False)
                bar.start()
                task = bar.add_task("sweep", total=len(pts), completed=len(done), last="")
            for fut in as_completed(list(futs)):
                p = futs[fut]
                try:
                    row = fut.result()
                except Exception as e:  # noqa: BLE001 - worker died (KilledWorker) or similar
                    row = {k: v for k, v in p.items() if not k.startswith("_")}
                    row.update({k: None for k in RESULT_KEYS})
                    row["status"] = _one_line(e)
                if row.get("status") != "ok":
                    failed += 1
                    meta.setdefault("first_failure", f"{p['id']}: {row.get('status')}")
                rows[p["id"]] = row
                flush()
                if bar is not None:
                    bar.update(task, advance=1, last=f"{p['id']}: {row.get('status')}"[:80])
        finally:
            if bar is not None:
                bar.stop()
            client.close()
            if cluster is not None:
                cluster.close()
    else:
        flush()
    meta.update({"finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "failed": failed,
                 "wall_s": time.perf_counter() - t0})
    write_json(out / "sweep.json", meta)
    return csv_path


# ----------------------------------------------------------------------------- phase diagram


def _num(s):
    if s is None or s == "":
        return None
    try:
        v = float(s)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _ok_rows(out) -> list[dict]:
    rows = []
    for r in read_results(Path(out) / "results.csv"):
        if r.get("status") != "ok":
            continue
        d = {k: _num(r.get(k)) for k in ("alpha", "freq", "gravity", "static_load", "seed", "amplitude",
                                           "a_over_g", "largest_cluster_fraction", "height_kept", "persistence",
                                           "rods_left", "contacts_per_rod", "cv_e")}
        if d["a_over_g"] is None and None not in (d["freq"], d["amplitude"], d["gravity"]):
            d["a_over_g"] = 4 * math.pi**2 * d["freq"] ** 2 * d["amplitude"] / d["gravity"]
        if d["alpha"] is None or d["a_over_g"] is None or d["largest_cluster_fraction"] is None:
            continue
        d["static_load"] = d["static_load"] or 0.0
        d["stable"] = str(r.get("stable")).strip().lower() in ("true", "1", "yes")
        d["ag"] = float(f"{d['a_over_g']:.4g}")
        rows.append(d)
    return rows


def _crossing(xs, ys, level=0.5):
    """First upward crossing of ``level`` by ys(xs), interpolated in log x.

    Returns (x*, err, lo, hi, note): err = half the bracketing interval; when no crossing,
    x* is None and the note says on which side of the range it lies.
    """
    pairs = sorted(zip(xs, ys))
    xs = [p[0] for p in pairs]
    ys = [p[1] for p in pairs]
    if all(y >= level for y in ys):
        return None, None, None, xs[0], f"below {xs[0]:g} (all points at or above {level:g})"
    if all(y < level for y in ys):
        return None, None, xs[-1], None, f"above {xs[-1]:g} (all points below {level:g})"
    # the last crossing from below (beyond it every point is at or above the level)
    i = max(j for j in range(len(ys)) if ys[j] < level)
    if i == len(ys) - 1:
        return None, None, xs[-1], None, f"above {xs[-1]:g} (largest alpha below {level:g})"
    x0, x1, y0, y1 = xs[i], xs[i + 1], ys[i], ys[i + 1]
    t = (level - y0) / (y1 - y0) if y1 != y0 else 0.5
    x = math.exp(math.log(x0) + t * (math.log(x1) - math.log(x0)))
    note = "interpolated" if all(y >= level for y in ys[i + 1:]) and all(y < level for y in ys[:i + 1]) \
        else "interpolated (non-monotonic: last crossing)"
    return x, 0.5 * (x1 - x0), x0, x1, note


def _bracketed(alphas, by_alpha, value, rng, n_boot):
    """Crossing of 0.5 by the seed mean of ``value(row)`` against alpha, with a bootstrap over seeds."""
    mean = [sum(value(r) for r in by_alpha[a]) / len(by_alpha[a]) for a in alphas]
    x, err, lo, hi, note = _crossing(alphas, mean)
    boot = None
    if max(len(v) for v in by_alpha.values()) > 1 and x is not None:
        vals = []
        for _ in range(n_boot):
            bm = [sum(value(rng.choice(by_alpha[a])) for _ in by_alpha[a]) / len(by_alpha[a]) for a in alphas]
            bx = _crossing(alphas, bm)[0]
            if bx is not None:
                vals.append(math.log(bx))
        if len(vals) > 1:
            m = sum(vals) / len(vals)
            boot = x * (sum((v - m) ** 2 for v in vals) / (len(vals) - 1)) ** 0.5  # log spread in alpha units
    return x, err, lo, hi, boot, note


def alpha_star(rows: list[dict], n_boot: int = 200, seed: int = 0) -> list[dict]:
    """Critical aspect ratio for each (a/g, gravity, static load) from ok rows (see :func:`_ok_rows`).

    ``alpha_star``: where the fraction of seeds judged ``stable`` (the verdict of
    :mod:`rodwarp.verdict`: height kept, persistence and the contact cluster) crosses 1/2,
    interpolated in log alpha; ``err`` is half the bracketing interval, ``boot_std`` the
    bootstrap spread over seeds (when a point has several). ``alpha_star_f``: the same on
    the seed-mean largest-cluster fraction f crossing 0.5 (the paper's Fig. 4H measure).
    """
    import random

    rng = random.Random(seed)
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["ag"], r["gravity"], r["static_load"]), []).append(r)
    out = []
    for (ag, g, s), rs in sorted(groups.items(), key=lambda kv: (kv[0][2], kv[0][1], kv[0][0])):
        by_alpha: dict = {}
        for r in rs:
            by_alpha.setdefault(r["alpha"], []).append(r)
        alphas = sorted(by_alpha)
        nseeds = max(len(v) for v in by_alpha.values())
        x, err, lo, hi, boot, note = _bracketed(alphas, by_alpha, lambda r: float(r["stable"]), rng, n_boot)
        xf, errf, lof, hif, bootf, notef = _bracketed(alphas, by_alpha, lambda r: r["largest_cluster_fraction"],
                                                     rng, n_boot)
        out.append({"a_over_g": ag, "gravity": g, "static_load": s, "n_alphas": len(alphas), "seeds": nseeds,
                    "alpha_star": x, "err": err, "bracket_lo": lo, "bracket_hi": hi, "boot_std": boot, "note": note,
                    "alpha_star_f": xf, "err_f": errf, "bracket_lo_f": lof, "bracket_hi_f": hif,
                    "boot_std_f": bootf, "note_f": notef})
    return out


def phase_diagram(out) -> list[Path]:
    """Figures and the alpha* table of a sweep directory (reads ``out/results.csv``).

    Writes ``phase_cv_e.png`` (Fig. 4L: sigma_e/mu_e against a/g, coloured by stability, with
    shaded stable/unstable regions), ``phase_f_alpha.png`` (Fig. 4H: f against alpha for each
    a/g), ``phase_verdict_alpha.png`` (height kept and persistence against alpha, the verdict's
    thresholds drawn), ``phase_f_ag.png`` (Fig. 4I: f against a/g for each alpha and static load),
    ``alpha_star.csv`` and ``phase_alpha_star.png`` (alpha* against a/g with its uncertainty).
    Returns the paths written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    rows = _ok_rows(out)
    if not rows:
        raise RodwarpError(f"{out / 'results.csv'} has no 'ok' rows with results: nothing to plot")
    written = []
    blue, red = "#1f5fbf", "#c62828"

    # Fig. 4L: cv_e against a/g
    fig, ax = plt.subplots(figsize=(5.5, 4))
    cv = [r for r in rows if r["cv_e"] is not None]
    ags = sorted({r["ag"] for r in rows})
    if cv:
        st = [r["cv_e"] for r in cv if r["stable"]]
        un = [r["cv_e"] for r in cv if not r["stable"]]
        ymax = max(r["cv_e"] for r in cv) * 1.15 + 1e-9
        ymin = min(0.0, min(r["cv_e"] for r in cv))
        # one horizontal boundary that best separates the classes; shaded on each side
        if st and un:
            cands = sorted({r["cv_e"] for r in cv})
            cuts = [0.5 * (a + b) for a, b in zip(cands, cands[1:])] or cands
            hi_stable = (sum(st) / len(st)) >= (sum(un) / len(un))

            def acc(c):
                return sum((r["cv_e"] >= c) == (r["stable"] == hi_stable) for r in cv)

            cut = max(cuts, key=acc)
            top, bottom = (blue, red) if hi_stable else (red, blue)
            ax.axhspan(cut, ymax, color=top, alpha=0.12, lw=0)
            ax.axhspan(ymin, cut, color=bottom, alpha=0.12, lw=0)
            ax.axhline(cut, color="0.4", ls=":", lw=0.8)
        else:
            ax.axhspan(ymin, ymax, color=blue if st else red, alpha=0.12, lw=0)
        for flag, col, lab in ((True, blue, "stable"), (False, red, "unstable")):
            sel = [r for r in cv if r["stable"] == flag]
            if sel:
                ax.scatter([r["a_over_g"] for r in sel], [r["cv_e"] for r in sel], c=col, label=lab, s=28,
                           edgecolors="k", linewidths=0.4, zorder=3)
        ax.set_ylim(ymin, ymax)
        ax.legend(fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("a/g")
    ax.set_ylabel("sigma_e / mu_e")
    ax.set_title("entanglement phase diagram (cf. Fig. 4L)", fontsize=9)
    fig.tight_layout()
    p = out / "phase_cv_e.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    written.append(p)

    def mean_by(rs, key, value="largest_cluster_fraction"):
        d: dict = {}
        for r in rs:
            if r[value] is not None:
                d.setdefault(r[key], []).append(r[value])
        ks = sorted(d)
        return ks, [sum(d[k]) / len(d[k]) for k in ks], [(max(d[k]) - min(d[k])) / 2 for k in ks]

    # Fig. 4H: f against alpha for each a/g (and static load when several)
    fig, ax = plt.subplots(figsize=(5.5, 4))
    loads = sorted({r["static_load"] for r in rows})
    for s in loads:
        for ag in ags:
            sel = [r for r in rows if r["ag"] == ag and r["static_load"] == s]
            if not sel:
                continue
            xs, ys, es = mean_by(sel, "alpha")
            lab = f"a/g = {ag:.3g}" + (f", F~ = {s:g}" if len(loads) > 1 else "")
            ax.errorbar(xs, ys, yerr=es if any(es) else None, fmt="o-", ms=4, capsize=2, label=lab)
    ax.axhline(0.5, ls=":", color="0.5", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("aspect ratio alpha")
    ax.set_ylabel("largest contact cluster fraction f")
    ax.set_ylim(0, 1.05)
    ax.set_title("f against alpha (cf. Fig. 4H)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    p = out / "phase_f_alpha.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    written.append(p)

    # the verdict's measures against alpha: height kept and persistence, with their thresholds
    from rodwarp.verdict import DEFAULT_THRESHOLDS as thr

    if any(r["height_kept"] is not None for r in rows):
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        for ax, value, label, level in ((axes[0], "height_kept", "height kept h at the end", thr.height_kept),
                                        (axes[1], "persistence", "persistence tau", thr.persistence)):
            for j, s in enumerate(loads):
                for k, ag in enumerate(ags):
                    sel = [r for r in rows if r["ag"] == ag and r["static_load"] == s and r[value] is not None]
                    if not sel:
                        continue
                    col = f"C{(j * len(ags) + k) % 10}"
                    xs, ys, _ = mean_by(sel, "alpha", value)
                    ax.plot(xs, ys, "-", color=col, lw=1,
                            label=f"a/g = {ag:.3g}" + (f", F~ = {s:g}" if len(loads) > 1 else ""))
                    for flag, face in ((True, col), (False, "white")):
                        pts_ = [r for r in sel if r["stable"] == flag]
                        ax.scatter([r["alpha"] for r in pts_], [r[value] for r in pts_], s=26, facecolors=face,
                                   edgecolors=col, zorder=3)
            ax.axhline(level, ls=":", color="tab:red", lw=1, label=f"threshold {level:g}")
            ax.set_xscale("log")
            ax.set_xlabel("aspect ratio alpha")
            ax.set_ylabel(label)
            ax.set_ylim(0, 1.05)
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=7)
        axes[1].set_title("filled: stable, open: unstable", fontsize=8)
        fig.suptitle("stability verdict against alpha (height kept, persistence)", fontsize=9)
        fig.tight_layout()
        p = out / "phase_verdict_alpha.png"
        fig.savefig(p, dpi=120)
        plt.close(fig)
        written.append(p)

    # Fig. 4I: f against a/g for each alpha and static load
    fig, ax = plt.subplots(figsize=(5.5, 4))
    markers = "osD^v<>ph*"
    for j, s in enumerate(loads):
        for a in sorted({r["alpha"] for r in rows}):
            sel = [r for r in rows if r["alpha"] == a and r["static_load"] == s]
            if not sel:
                continue
            xs, ys, es = mean_by(sel, "ag")
            ax.errorbar(xs, ys, yerr=es if any(es) else None, fmt=markers[j % len(markers)] + "-", ms=4,
                        capsize=2, label=f"alpha = {a:g}, F~ = {s:g}")
    ax.axhline(0.5, ls=":", color="0.5", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("a/g")
    ax.set_ylabel("largest contact cluster fraction f")
    ax.set_ylim(0, 1.05)
    ax.set_title("f against a/g (cf. Fig. 4I)", fontsize=9)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    p = out / "phase_f_ag.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    written.append(p)

    # alpha* table and figure
    table = alpha_star(rows)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(table[0]), lineterminator="\n")
    w.writeheader()
    for t in table:
        w.writerow({k: _cell(v) for k, v in t.items()})
    p = out / "alpha_star.csv"
    write_text(p, buf.getvalue())
    written.append(p)

    fig, ax = plt.subplots(figsize=(5.5, 4))
    amin = min(r["alpha"] for r in rows)
    amax = max(r["alpha"] for r in rows)
    for j, s in enumerate(loads):
        sel = [t for t in table if t["static_load"] == s]
        col = f"C{j}"
        lab = f"F~ = {s:g}"
        pts_ = [t for t in sel if t["alpha_star"] is not None]
        if pts_:
            yerr = [max(t["err"] or 0, t["boot_std"] or 0) for t in pts_]
            ax.errorbar([t["a_over_g"] for t in pts_], [t["alpha_star"] for t in pts_], yerr=yerr, fmt="o-",
                        color=col, capsize=3, label=lab)
            lab = None
        below = [t for t in sel if t["alpha_star"] is None and t["bracket_hi"] is not None]
        above = [t for t in sel if t["alpha_star"] is None and t["bracket_lo"] is not None]
        if below:
            ax.scatter([t["a_over_g"] for t in below], [t["bracket_hi"] for t in below], marker="v", color=col,
                       label=(lab + ": " if lab else "") + "alpha* below the smallest alpha")
        if above:
            ax.scatter([t["a_over_g"] for t in above], [t["bracket_lo"] for t in above], marker="^", color=col,
                       label=(lab + ": " if lab else "") + "alpha* above the largest alpha")
    ax.axhline(100, ls="--", color="0.5", lw=0.8, label="paper: alpha* ~ 100 at a/g ~ 1")
    ax.axvline(1, ls=":", color="0.7", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_ylim(amin / 1.5, amax * 1.5)
    ax.set_xlabel("a/g")
    ax.set_ylabel("critical aspect ratio alpha* (half the seeds stable)")
    ax.set_title("critical aspect ratio", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    p = out / "phase_alpha_star.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    written.append(p)
    return written
