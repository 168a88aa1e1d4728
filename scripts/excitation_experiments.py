"""The paper's excitation experiment (Fig. 1C-F) in silico: runs, resume and report.

``run`` makes the runs of the plan below that are not finished, ``--workers`` processes at a
time, in priority order (each alpha's first seed before any second seed; the controls after two
seeds). A run is ``rodwarp simulate --protocol excitation`` with the paper's defaults; a run of
the main set shakes for the paper's T = 100 s, and ``--until S`` stops it (SIGINT, after a
checkpoint) once S seconds are shaken, so that every alpha reaches 20 s (100 cycles) before any
goes on; a later ``run`` resumes it (``--resume``) toward 100 s:

    python scripts/excitation_experiments.py run --runs RUNS_DIR --until 20 [--workers 2] [--only main]
    python scripts/excitation_experiments.py report --runs RUNS_DIR

``report`` reads every run folder (a finished run's summary.json; a run still going or
stopped: its metrics.csv up to its last checkpoint) and writes
``benchmarks/results/excitation.json`` and ``.md`` and the figures ``excitation_fig1e.png``
(y_c / y_c(0) landed per cycle, every seed) and ``excitation_fig1f.png`` (tau against alpha).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shlex
import signal
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results"
BASE = ["--protocol", "excitation", "--quiet", "--checkpoint-every", "1"]
#: the main set's alphas (the experiments' five, Fig. 1E's 125) and seeds
ALPHAS = (38, 66, 76, 100, 125, 200)
SEEDS = (0, 1, 2)
#: the controls: name -> (alphas, seeds, extra arguments); each shakes 20 s
CONTROLS = {
    "open": ((100, 200), (0, 1), ["--container-diameter", "0"]),
    "mu0.4": ((100, 200), (0, 1), ["--mu", "0.4"]),
    "tube100": ((100, 200), (0, 1), ["--tube-diameter", "0.1"]),
    "rigid": ((200,), (0, 1), ["--rod-model", "rigid"]),
    # N: the lab protocol's 2160 rods at alpha 100 (a cylinder of radius l filled to 1 l) in the same tube
    "n2160": ((100,), (0, 1), ["--n-rods", "2160"]),
}
CONTROL_S = 20.0
#: ``rodwarp simulate``'s exit code for a run the engine stopped (rods overlapping beyond a quarter
#: diameter); such a run is made again from the start with RETRY_ARGS, in a folder named with
#: RETRY_SUFFIX (the protocol's default is 20 sweeps, since 10 blew up at alpha 66 and 100)
BLEW_UP = 3
RETRY_ARGS = ["--iterations", "40"]
RETRY_SUFFIX = "_it40"


def plan() -> list[dict]:
    """Every run, in the order ``run`` takes them: what it is, its folder name, its command's
    arguments and how long it shakes in the end (s)."""
    jobs = []

    def add(kind, alpha, seed, extra, duration):
        jobs.append({"kind": kind, "alpha": alpha, "seed": seed, "name": f"{kind}_alpha{alpha}_seed{seed}",
                     "args": [*BASE, "--alpha", str(alpha), "--seed", str(seed), "--duration", f"{duration:g}",
                              *extra], "duration": duration})

    # Fig. 1A-B: the tube removed, no shaking (the release is the test), the paper's N
    for a in (38, 200):
        add("still", a, 0, ["--lift-duration", "2"], 0.0)
    order = (100, 200, 66, 76, 125, 38)  # the cheapest informative first; alpha 38's 3040 rods cost most
    for a in order:
        add("main", a, SEEDS[0], [], 100.0)
    add("main", 100, SEEDS[1], [], 100.0)
    for name in ("open", "mu0.4", "tube100", "n2160"):  # the controls at alpha 100 (the cheap ones) first
        add(name, 100, CONTROLS[name][1][0], CONTROLS[name][2], CONTROL_S)
    for a in (66, 76, 200):
        add("main", a, SEEDS[1], [], 100.0)
    add("rigid", 200, 0, CONTROLS["rigid"][2], CONTROL_S)
    for a in order[4:]:
        add("main", a, SEEDS[1], [], 100.0)
    for name in ("open", "mu0.4", "tube100"):
        add(name, 200, CONTROLS[name][1][0], CONTROLS[name][2], CONTROL_S)
    for a in order:
        add("main", a, SEEDS[2], [], 100.0)
    for name, (alphas, seeds, extra) in CONTROLS.items():
        for a in alphas:
            for s in seeds[1:]:
                add(name, a, s, extra, CONTROL_S)
    add("main", 333, 0, [], 10.0)  # Fig. 1D
    for a in (38, 200):
        add("still", a, 1, ["--lift-duration", "2"], 0.0)
    return jobs


def _params(folder: Path) -> dict | None:
    try:
        return json.loads((folder / "rodwarp-run.json").read_text())["parameters"]
    except (FileNotFoundError, KeyError, json.JSONDecodeError):
        return None


def shaken(folder: Path) -> float:
    """Seconds shaken in ``folder``'s metrics.csv (written at each checkpoint); 0 before."""
    p = _params(folder)
    if p is None or not (folder / "metrics.csv").exists():
        return 0.0
    t0 = p["pour_duration"] + p["lift_duration"]
    last = 0.0
    with open(folder / "metrics.csv") as fh:
        for r in csv.DictReader(fh):
            if r["stage"] == "shake":
                last = float(r["time"]) - t0
    return max(last, 0.0)


def _done(folder: Path, job: dict, until: float) -> bool:
    if (folder / "summary.json").exists():
        return True
    return job["duration"] > 0 and shaken(folder) >= min(until, job["duration"]) - 1e-6


def run(args) -> int:
    runs = Path(args.runs)
    runs.mkdir(parents=True, exist_ok=True)
    exe = str(Path(sys.executable).with_name("rodwarp"))
    only = set(args.only.split(",")) if args.only else None
    todo = [j for j in plan() if (only is None or j["kind"] in only) and not _done(runs / j["name"], j, args.until)]
    active: list[tuple[dict, subprocess.Popen, float]] = []
    failed = 0
    while todo or active:
        while todo and len(active) < args.workers:
            job = todo.pop(0)
            folder = runs / job["name"]
            cmd = [exe, "simulate", *job["args"], "--out", str(folder)]
            if any(folder.glob("checkpoints/ckpt_*.npz")):
                cmd.append("--resume")
            print(f"{datetime.now(timezone.utc):%H:%M:%S} start {' '.join(shlex.quote(c) for c in cmd[1:])}",
                  flush=True)
            log = open(runs / f"{job['name']}.log", "a")
            # a runner started in the background inherits SIGINT ignored, and Python then keeps
            # it ignored: restore it so that the stop below is the run's own clean interruption
            active.append((job, subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL)),
                           time.perf_counter()))
        time.sleep(args.poll)
        for item in list(active):
            job, proc, t0 = item
            folder = runs / job["name"]
            rc = proc.poll()
            if rc is None and job["duration"] > args.until and shaken(folder) >= args.until - 1e-6:
                proc.send_signal(signal.SIGINT)  # stopped after a checkpoint; `run` resumes it later
                try:
                    rc = proc.wait(timeout=120)
                except subprocess.TimeoutExpired:  # checkpoints are atomic: a kill loses nothing saved
                    proc.kill()
                    rc = proc.wait()
                print(f"  {job['name']}: stopped at {shaken(folder):.1f} s shaken (--until {args.until:g})", flush=True)
                rc = 0
            if rc is not None:
                active.remove(item)
                print(f"  {job['name']}: exit {rc} after {time.perf_counter() - t0:.0f} s", flush=True)
                if rc == BLEW_UP and "--iterations" not in job["args"]:
                    # the engine stopped the run at an overlap it cannot resolve (exit 3, the cause in its
                    # log): the same run from the start with more Gauss-Seidel sweeps, next in line
                    retry = {**job, "name": job["name"] + RETRY_SUFFIX, "args": [*job["args"], *RETRY_ARGS]}
                    if not _done(runs / retry["name"], retry, args.until):
                        todo.insert(0, retry)
                    continue
                failed += rc != 0
    return 1 if failed else 0


# ----------------------------------------------------------------------------- report


def _rows(folder: Path) -> list[dict]:
    with open(folder / "metrics.csv") as fh:
        return list(csv.DictReader(fh))


def collect(folder: Path) -> dict | None:
    """One run's record: its parameters, rod model, cost, and the shaking's measures (a run
    not finished: from its metrics.csv up to its last checkpoint, ``complete`` False)."""
    from rodwarp.experiments import ProtocolParams
    from rodwarp.experiments.protocols.excitation import excitation_shake, sources
    from rodwarp.experiments._params import rod_model_rule
    from rodwarp.experiments._verdict import DEFAULT_THRESHOLDS

    p = _params(folder)
    if p is None or not (folder / "metrics.csv").exists():
        return None
    manifest = json.loads((folder / "rodwarp-run.json").read_text())
    params = ProtocolParams(**{k: tuple(v) if isinstance(v, list) else v for k, v in p.items()})
    rows = _rows(folder)
    t_shake = p["pour_duration"] + p["lift_duration"]
    summary = json.loads((folder / "summary.json").read_text()) if (folder / "summary.json").exists() else None
    rec = {"run": folder.name, "alpha": p["alpha"], "seed": p["seed"], "n_rods": params.rods,
           "length_m": p["length"], "diameter_m": params.diameter, "mu": p["mu"],
           "rod_model": rod_model_rule(params)["rod_model"], "vertices": params.n_vertices,
           "contact_law": p["contact_law"] or "exact", "container_diameter_m": p["container_diameter"],
           "tube_diameter_m": p["tube_diameter"], "freq_hz": p["freq"], "amplitude_m": p["amplitude"],
           "a_over_g": params.a_over_g, "duration_s": p["duration"], "complete": summary is not None,
           "iterations": p["iterations"], "status": manifest.get("status"),
           "error": (manifest.get("error") or {}).get("message") if isinstance(manifest.get("error"), dict)
           else manifest.get("error"),
           "sources": sources(params)}
    pour = [r for r in rows if r["stage"] == "pour"]
    rel = [r for r in rows if r["stage"] == "release"]
    if pour:
        rec["pour"] = {"centroid_height_m": float(pour[-1]["centroid_height"]),
                       "top_height_m": float(pour[-1]["top_height"]),
                       "contacts_per_rod": float(pour[-1]["contacts_per_rod"])}
    if rel and pour:
        rec["release"] = {"height_kept": float(rel[-1]["centroid_height"]) / float(pour[-1]["centroid_height"]),
                          "spread_over_tube": float(rel[-1]["spread_radius"]) / (0.5 * p["tube_diameter"]),
                          "largest_cluster_fraction": float(rel[-1]["largest_cluster_fraction"])}
    wall = _wall_by_stage(folder, summary)
    rec["wall_s"] = wall
    if any(r["stage"] == "shake" and float(r["time"]) > t_shake for r in rows):
        sh = excitation_shake(params, rows, t_shake, DEFAULT_THRESHOLDS)
        rec["shake"] = {k: sh[k] for k in ("shaken_s", "tau", "landed_height_after_cycles", "formed",
                                           "highest_rod_bottom_max_m", "warnings", "cohesion")}
        rec["shake"]["landed"] = {k: sh["landed"][k] for k in ("cycle", "centroid_height_ratio",
                                                              "largest_cluster_fraction", "entangled")}
        if wall.get("shake"):
            rec["cpu_s_per_sim_s"] = wall["shake"] / sh["shaken_s"]
    return rec


def _wall_by_stage(folder: Path, summary: dict | None) -> dict:
    """Wall seconds of each stage (one thread per process): summary.json's, else the newest
    checkpoint's record."""
    dts = summary["dt"] if summary else None
    if dts is None:
        from rodwarp.rodset.trajectory import latest_checkpoint

        ck = latest_checkpoint(folder / "checkpoints")
        dts = ck[1]["dts"] if ck else {}
    return {k: v.get("wall_s") for k, v in dts.items()}


def blew_up(rec: dict) -> bool:
    """The engine stopped the run (rods overlapping beyond its limit; ``simulate`` exit 3)."""
    return rec.get("status") == "failed" and "blew up" in (rec.get("error") or "")


def _fmt(v, nd=3):
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.{nd}g}"
    return str(v)


def outcome(rec: dict) -> str:
    """lost, kept or enhanced cohesion over the shaking so far: kept when every landed cycle
    is entangled, lost when the last five are not, enhanced when a unit formed (Fig. 1E (i)) and
    the last five are entangled; mixed otherwise."""
    sh = rec.get("shake")
    if not sh:
        return "-"
    e = sh["landed"]["entangled"]
    last = e[-5:]
    if sh["formed"] and all(last):
        return "enhanced"
    if all(e):
        return "kept"
    if not any(last):
        return "lost"
    return "mixed"


#: the fewest cycles a run must have shaken to enter alpha*'s bracket (10 s at 5 Hz)
STAR_CYCLES = 50


def alpha_star(records: list[dict], min_cycles: int = STAR_CYCLES) -> dict:
    """alpha* by tau as a bracket: the largest alpha whose every seed has tau < 0.5 and the
    smallest alpha above it whose every seed has tau >= 0.5, with the seed counts; no point value.
    tau is taken over each run's first ``min_cycles`` cycles, so that runs shaken for different
    times compare alike; shorter runs are left out."""
    by = {}
    for r in records:
        e = (r.get("shake") or {}).get("landed", {}).get("entangled", [])
        if len(e) >= min_cycles:
            by.setdefault(r["alpha"], []).append(float(np.mean(e[:min_cycles])))
    alphas = sorted(by)
    below = [a for a in alphas if all(t < 0.5 for t in by[a])]
    above = [a for a in alphas if all(t >= 0.5 for t in by[a])]
    lo = max(below, default=None)
    hi = min((a for a in above if lo is None or a > lo), default=None)
    return {"below": lo, "above": hi, "seeds": {f"{a:g}": len(by[a]) for a in alphas},
            "tau": {f"{a:g}": by[a] for a in alphas}, "cycles": min_cycles,
            "rule": f"alpha* lies between the largest alpha whose every seed has tau < 0.5 and the next alpha "
                    f"whose every seed has tau >= 0.5, tau over each run's first {min_cycles} cycles (runs shaken "
                    f"for fewer are left out)"}


def control_effects(main: list[dict], ctrl: list[dict]) -> list[dict]:
    """Each control against the paper's scene at its alpha: tau and the landed y_c / y_c(0)
    after 10 and 50 cycles, the control's seeds against the main runs' range over seeds (the
    seed spread), over the cycles both have shaken; ``moves`` when the control lies outside
    that range."""
    def measures(r, cycles):
        L = r["shake"]["landed"]
        k = min(cycles, len(L["entangled"]))
        e = L["entangled"][:k]
        y = L["centroid_height_ratio"]
        return {"tau": float(np.mean(e)) if e else None, "y10": y[9] if len(y) >= 10 else None,
                "y50": y[49] if len(y) >= 50 else None}

    out = []
    kinds = sorted({r["run"].split("_alpha")[0] for r in ctrl})
    for kind in kinds:
        for a in sorted({r["alpha"] for r in ctrl if r["run"].startswith(kind + "_")}):
            cs = [r for r in ctrl if r["run"].startswith(kind + "_") and r["alpha"] == a and r.get("shake")]
            ms = [r for r in main if r["alpha"] == a and r.get("shake")]
            if not cs or not ms:
                continue
            n = min(len(r["shake"]["landed"]["entangled"]) for r in cs + ms)
            if n < 10:  # fewer cycles than tell a collapse from a standing clump here (half height after 4-11)
                continue
            cm = [measures(r, n) for r in cs]
            mm = [measures(r, n) for r in ms]
            row = {"control": kind, "alpha": a, "cycles": n, "control_seeds": len(cs), "main_seeds": len(ms)}
            moves = False
            for key in ("tau", "y10", "y50"):
                cv = [m[key] for m in cm if m[key] is not None]
                mv = [m[key] for m in mm if m[key] is not None]
                row[key] = {"control": cv, "main": [min(mv), max(mv)] if mv else None}
                if cv and mv:
                    lo, hi = min(mv), max(mv)
                    pad = 0.02  # below this the landed heights of one run wander from cycle to cycle
                    moves |= any(v < lo - pad or v > hi + pad for v in cv)
            row["moves"] = moves
            out.append(row)
    return out


def report(args) -> int:
    from rodwarp._util import versions

    runs = Path(args.runs)
    recs = [r for d in sorted(runs.iterdir()) if d.is_dir() and (r := collect(d)) is not None]
    blown = [r for r in recs if blew_up(r)]
    # a run the engine stopped keeps its place in its table up to the stop (its "complete" column
    # says so); the runs at the generic 10 sweeps are listed apart, since the protocol's default is 20
    kept = [r for r in recs if not r["run"].startswith("sweeps10_")]
    order = lambda r: (r["alpha"], r["seed"], r["iterations"])  # noqa: E731
    main = sorted((r for r in kept if r["run"].startswith("main_") and r.get("shake")), key=order)
    ctrl = sorted((r for r in kept if not r["run"].startswith(("main_", "still_")) and r.get("shake")), key=order)
    still = [r for r in kept if r["run"].startswith("still_")]
    for r in recs:
        r["outcome"] = outcome(r)
    record = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "machine": _machine(),
              "versions": versions(), "command": "python scripts/excitation_experiments.py report --runs " + str(runs),
              "plan": plan(), "alpha_star": alpha_star(main), "controls": control_effects(main, ctrl), "runs": recs}
    OUT.mkdir(parents=True, exist_ok=True)
    from rodwarp.rodset.files import write_json

    write_json(OUT / "excitation.json", record)
    figs = [_fig1e(main), _fig1f(main, ctrl)]
    _write_md(OUT / "excitation.md", record, main, ctrl, still, blown, figs)
    print(f"{len(recs)} runs -> {OUT / 'excitation.md'}")
    return 0


def _machine() -> str:
    import platform

    cpu = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()}-core {cpu}"


def _fig1e(main: list[dict]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rodwarp.rodset.files import save_figure

    alphas = sorted({r["alpha"] for r in main if r.get("shake")})
    fig, ax = plt.subplots(figsize=(7, 4.2))
    cmap = plt.get_cmap("viridis")
    for i, a in enumerate(alphas):
        col = cmap(i / max(len(alphas) - 1, 1))
        for k, r in enumerate(x for x in main if x["alpha"] == a and x.get("shake")):
            L = r["shake"]["landed"]
            ax.plot(L["cycle"], L["centroid_height_ratio"], color=col, lw=1, alpha=0.85,
                    label=f"alpha {a:g}" if k == 0 else None)
    ax.axhline(0.5, color="tab:red", ls=":", lw=1, label="tau's height threshold 0.5")
    ax.set_xlabel("cycles N = t f")
    ax.set_ylabel("landed y_c / y_c(0)")
    ax.set_title("Fig. 1E in silico: 5 Hz, 25 mm, 150 mm container (every seed)", fontsize=10)
    ax.legend(fontsize=8, ncol=2)
    name = "excitation_fig1e.png"
    save_figure(fig, OUT / name, dpi=130)
    plt.close(fig)
    return name


def _fig1f(main: list[dict], ctrl: list[dict]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rodwarp.rodset.files import save_figure

    fig, ax = plt.subplots(figsize=(6, 4))
    for recs, mk, lab in ((main, "o", "paper's scene"), (ctrl, "x", "controls")):
        pts = [(r["alpha"], r["shake"]["tau"]["tau"]) for r in recs if r.get("shake")]
        if pts:
            a, t = zip(*pts)
            ax.scatter(a, t, marker=mk, label=lab, alpha=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("alpha")
    ax.set_ylabel("tau = t_entangled / T (over the cycles shaken)")
    ax.set_ylim(-0.05, 1.05)
    ax.set_title("Fig. 1F in silico (every seed)", fontsize=10)
    ax.legend(fontsize=8)
    name = "excitation_fig1f.png"
    save_figure(fig, OUT / name, dpi=130)
    plt.close(fig)
    return name


def _row(r: dict) -> str:
    sh = r.get("shake") or {}
    at = sh.get("landed_height_after_cycles", {})
    tau = sh.get("tau", {})
    box = "open" if not r["container_diameter_m"] else f"{r['container_diameter_m'] * 1e3:g} mm"
    model = r["rod_model"] if r["rod_model"] == "rigid" else f"{r['rod_model']} ({r['vertices']} v)"
    return (f"| {r['alpha']:g} | {r['seed']} | {r['n_rods']} | {model} | {r['iterations']} | {r['mu']:g} | "
            f"{box} | "
            f"{r['tube_diameter_m'] * 1e3:g} mm | {_fmt(sh.get('shaken_s'))} | {_fmt(tau.get('tau'), 2)} "
            f"({_fmt((tau.get('at_height') or {}).get('0.4'), 2)}, {_fmt((tau.get('at_height') or {}).get('0.6'), 2)}) | "
            f"{_fmt(tau.get('tau_first'), 2)} | {_fmt(at.get('10'), 2)} | {_fmt(at.get('50'), 2)} | "
            f"{_fmt(at.get('100'), 2)} | {_fmt(at.get('500'), 2)} | {r['outcome']} | "
            f"{len(sh.get('formed', []))} | {_fmt(r.get('cpu_s_per_sim_s'))} | "
            f"{'yes' if r['complete'] else 'stopped by the engine' if blew_up(r) else 'no'} |")


HEAD = ("| alpha | seed | N | rods | sweeps | mu | container | tube | shaken (s) | tau (at 0.4, 0.6) | tau_first | y/y0 @10 | @50 | @100 | "
        "@500 | cohesion | units formed | CPU-s per sim-s | complete |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def _write_md(path: Path, record: dict, main, ctrl, still, blown, figs) -> None:
    from rodwarp.rodset.files import atomic_path

    st = record["alpha_star"]
    lines = [
        "# The excitation experiment in silico (Fig. 1C-F)", "",
        f"Written by `{record['command']}` on {record['date']} ({record['machine']}, rodwarp "
        f"{record['versions'].get('rodwarp')}, warp {record['versions'].get('warp')}). One thread per run.", "",
        "Every run: `rodwarp simulate --protocol excitation`, the exact contact law (Signorini and the Coulomb "
        "cone, Gauss-Seidel), steel rods (E 200 GPa, 7850 kg/m^3), g = 9.81 m/s^2, N = 1.25e6 / (d l^2) (d, l in "
        "mm), poured into a 60 mm tube inside a 150 mm container, the tube removed, 1 s at rest, then the floor "
        "and the container's wall shaken at 5 Hz, 25 mm (a/g = 2.5), unless a column says otherwise. Measure: "
        "per cycle, the landed centroid height y_c / y_c(0) (the lowest of 8 samples a cycle) and the largest "
        "contact cluster's share f at that sample; a cycle is entangled when y_c / y_c(0) >= 0.5 and f >= 0.8 "
        "(tau at 0.4 and 0.6 beside it); "
        "tau = entangled cycles / cycles shaken; tau_first = cycles before the first that is not / cycles "
        "shaken. Runs not complete are reported to their last checkpoint (the shaken seconds column).", "",
        "## Fig. 1E-F: the paper's scene", "", HEAD, *[_row(r) for r in main], "",
        f"alpha* by tau: above {_fmt(st['below'])} and at most {_fmt(st['above'])} (seeds per alpha: "
        f"{st['seeds']}; {st['rule']}).", "",
        "## Controls", "", HEAD, *[_row(r) for r in ctrl], "",
        "Each control against the paper's scene at the same alpha, over the cycles both have shaken: the "
        "control's values against the range of the main runs' seeds (the seed spread). 'moves' when a control "
        "lies outside that range by more than 0.02.", "",
        "| control | alpha | cycles | seeds (control, main) | tau: control / main range | y/y0 @10 | y/y0 @50 | moves |",
        "|---|---|---|---|---|---|---|---|",
        *[f"| {c['control']} | {c['alpha']:g} | {c['cycles']} | {c['control_seeds']}, {c['main_seeds']} | "
          + " | ".join(f"{', '.join(_fmt(v, 2) for v in c[k]['control'])} / "
                       f"{'-' if not c[k]['main'] else '-'.join(_fmt(v, 2) for v in c[k]['main'])}"
                       for k in ("tau", "y10", "y50"))
          + f" | {'yes' if c['moves'] else 'no'} |" for c in record["controls"]], "",
        "## Runs the engine stopped", "",
        "The protocol's default is 20 Gauss-Seidel sweeps because the first two runs at the generic 10 were "
        "stopped so (the `sweeps10_` rows); a run stopped at 20 keeps its row above up to the stop and is made "
        "again with 40 (its `_it40` row).", "",
        "| run | shaken (s) | sweeps | the engine's message |", "|---|---|---|---|",
        *[f"| {r['run']} | {_fmt((r.get('shake') or {}).get('shaken_s'))} | {r['iterations']} | {r['error']} |"
          for r in blown], "",
        "## Fig. 1A-B: the tube removed, no shaking", "",
        "| alpha | seed | N | rods | sweeps | height kept after release | spread / tube radius | f |",
        "|---|---|---|---|---|---|---|---|",
        *[f"| {r['alpha']:g} | {r['seed']} | {r['n_rods']} | {r['rod_model']} | {r['iterations']} | "
          f"{_fmt((r.get('release') or {}).get('height_kept'))} | {_fmt((r.get('release') or {}).get('spread_over_tube'))} | "
          f"{_fmt((r.get('release') or {}).get('largest_cluster_fraction'))} |" for r in still], "",
        *[f"![{f}]({f})" for f in figs], "",
    ]
    with atomic_path(path) as tmp:
        Path(tmp).write_text("\n".join(lines))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="make the runs not finished (resuming stopped ones)")
    r.add_argument("--runs", required=True, help="folder of the run folders")
    r.add_argument("--until", type=float, default=20.0, help="stop each main run once this many seconds are shaken")
    r.add_argument("--workers", type=int, default=2, help="runs at a time (one thread each)")
    r.add_argument("--only", default=None, help="comma-separated kinds: still, main, open, mu0.4, tube100, rigid, n2160")
    r.add_argument("--poll", type=float, default=10.0, help="seconds between looks at the runs")
    q = sub.add_parser("report", help="collect the runs into benchmarks/results/excitation.*")
    q.add_argument("--runs", required=True)
    args = ap.parse_args(argv)
    if args.cmd == "run":
        if args.workers < 1 or args.workers > (os.cpu_count() or 1):
            ap.error(f"--workers must be 1 to {os.cpu_count()} (the cores here)")
        return run(args)
    return report(args)


if __name__ == "__main__":
    sys.exit(main())
