"""What the excitation experiment's long runs cost: CPU-s per simulated second of shaking (issue 45).

The laboratory protocol (``rodwarp simulate --protocol lab``: rods poured into a cylinder of
radius l, settled 1 s, the cylinder lifted away, 1 s, then the plate shaken at 5 Hz, 25 mm, a/g
2.5; g = 9.81 m/s^2, mu 0.2, the exact contact law) at each alpha of the paper's excitation
experiment with its rods and its rod count N ~ 1.25e6 / (d l^2) (d, l in mm; docs/experiments.md):

| alpha | l (mm) | d (mm) | N | rods |
|---|---|---|---|---|
| 38 | 25 | 0.66 | 3030 | rigid (the rule's choice) |
| 66 | 50 | 0.76 | 658 | rigid |
| 76 | 50 | 0.66 | 758 | rigid |
| 100 | 50 | 0.5 | 1000 | rigid |
| 200 | 50 | 0.25 | 2000 | elastic, the resolution rule's vertices (3); and at 10 vertices, every elastic run's before the rule |

Each case is prepared once by the real command (pour, lift and a short shaking; seed 0; runs in
``runs/lab_cost``), whose end-of-lift checkpoint is kept. The shaking is then timed from that
state by ``benchmarks/lab_shake_timer.py`` (the steps alone, CPU time of the process, one core),
``REPEATS`` times. With ``RODWARP_BASELINE_PYTHON`` set to another checkout's Python, the same
script times that checkout on the same states, alternated with this one: same-run ratios. The
ten-vertex alpha-200 state is the baseline's model of the alpha-200 case.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks import common

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "runs" / "lab_cost"
TIMER = Path(__file__).with_name("lab_shake_timer.py")
REPEATS = 3
# (name, alpha, l (m), N, extra simulate options, simulated seconds of shaking timed)
CASES = (
    ("alpha38", 38, 0.025, 3030, [], 0.4),
    ("alpha66", 66, 0.05, 658, [], 0.4),
    ("alpha76", 76, 0.05, 758, [], 0.4),
    ("alpha100", 100, 0.05, 1000, [], 0.4),
    ("alpha200", 200, 0.05, 2000, ["--rod-model", "elastic"], 0.2),
    ("alpha200_v10", 200, 0.05, 2000, ["--rod-model", "elastic", "--vertices", "10"], 0.2),
)
#: the case a baseline checkout times in place of each case (its own model of the experiment)
BASELINE_STATE = {"alpha200": "alpha200_v10"}


def _args(alpha, length, n, extra):
    return ["--protocol", "lab", "--alpha", f"{alpha:g}", "--length", f"{length:g}", "--gravity", "9.81",
            "--n-rods", str(n), "--freq", "5", "--amplitude", "0.025", "--duration", "0.2", *extra]


def _prepare(name, alpha, length, n, extra) -> tuple[Path, dict]:
    """The case's end-of-lift checkpoint and what it holds (rod model, vertices per rod).

    Prepared once by the real command (``runs/lab_cost/NAME/prep``; a state already in
    ``NAME/state`` is reused: any run of the same command, whatever its shaking's length, holds
    the same state when the shaking starts)."""
    from rodwarp.experiments._params import ProtocolParams, rod_model_rule
    from rodwarp.rodset.trajectory import read_checkpoint_file

    prep = RUNS / name / "prep"
    ck = RUNS / name / "state" / "checkpoints" / "lift.npz"
    if not ck.exists():
        s, failure = common.simulate_once(prep, _args(alpha, length, n, extra), "lab_cost")
        if failure:
            raise RuntimeError(f"{name}: {failure}")
        ck.parent.mkdir(parents=True, exist_ok=True)
        for path in sorted((prep / "checkpoints").glob("ckpt_*.npz")):
            _, meta = read_checkpoint_file(path)
            if not meta["mid_stage"] and meta["stage"] == len(s["lab"]["stages"]) - 1:  # the shaking's start
                shutil.copy(prep / "initial.npz", ck.parent.parent / "initial.npz")
                shutil.copy(path, ck)
        if not ck.exists():
            raise RuntimeError(f"{name}: no end-of-lift checkpoint in {prep / 'checkpoints'}")
    arrays, meta = read_checkpoint_file(ck)
    known = ProtocolParams.__dataclass_fields__
    params = ProtocolParams(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in meta["parameters"].items()
                               if k in known})
    n_rods = int(params.rods)
    return ck, {"rod_model": rod_model_rule(params)["rod_model"], "n_vertices_per_rod": len(arrays["state_x"]) // n_rods,
                "state_time_s": float(meta["stage_t0"].get("lift", 0.0)) + params.lift_duration}


def _time(python: str, ck: Path, seconds: float) -> dict:
    r = subprocess.run([python, str(TIMER), str(ck), f"{seconds:g}"], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError((r.stderr.strip().splitlines() or ["failed"])[-1])
    return json.loads(r.stdout.strip().splitlines()[-1])


def _version(python: str) -> str:
    r = subprocess.run([python, "-c", "import rodwarp, pathlib, subprocess; p = pathlib.Path(rodwarp.__file__)"
                        ".parents[1]; print(subprocess.run(['git', '-C', str(p), 'rev-parse', '--short', 'HEAD'], "
                        "capture_output=True, text=True).stdout.strip() or rodwarp.__version__)"],
                       capture_output=True, text=True, cwd="/")  # not this checkout's folder: it would import it
    return r.stdout.strip() or "unknown"


def run(quick: bool, device: str) -> dict:
    RUNS.mkdir(parents=True, exist_ok=True)
    base = os.environ.get("RODWARP_BASELINE_PYTHON")
    cases = CASES[3:5] if quick else CASES
    states, preps = {}, {}
    for name, alpha, length, n, extra, _ in CASES if base else cases:
        # the preparation's walls are not timings (other runs may share the cores then)
        states[name], preps[name] = _prepare(name, alpha, length, n, extra)
    rows = []
    for name, alpha, length, n, extra, seconds in cases:
        now, before = [], []
        for _ in range(1 if quick else REPEATS):
            now.append(_time(sys.executable, states[name], seconds))
            common.log(f"lab_cost: {name} now {now[-1]['cpu_s_per_s']:.1f} CPU-s per s")
            if base:
                before.append(_time(base, states[BASELINE_STATE.get(name, name)], seconds))
                common.log(f"lab_cost: {name} baseline {before[-1]['cpu_s_per_s']:.1f} CPU-s per s")
        row = {"case": name, "alpha": alpha, "length_m": length, "n_rods": n, "options": extra, "seconds": seconds,
               **preps[name], "now": now, "now_cpu_s_per_s": float(np.median([r["cpu_s_per_s"] for r in now]))}
        if before:
            row["before"] = before
            row["before_state"] = BASELINE_STATE.get(name, name)
            row["before_cpu_s_per_s"] = float(np.median([r["cpu_s_per_s"] for r in before]))
            row["ratios"] = [b["cpu_s_per_s"] / a["cpu_s_per_s"] for a, b in zip(now, before)]
            row["speedup"] = float(np.median(row["ratios"]))
        rows.append(row)
        common.log(f"lab_cost: {name}: {row['now_cpu_s_per_s']:.1f} CPU-s per simulated second")
    return {"title": "The excitation experiment's cost: CPU-s per simulated second of shaking (paper's N)",
            "rows": rows, "baseline": _version(base) if base else None, "repeats": REPEATS,
            "hours_for_100_s": {r["case"]: r["now_cpu_s_per_s"] * 100 / 3600 for r in rows}}


def summary(rec: dict) -> list[dict]:
    out = []
    for r in rec["rows"]:
        out.append({"benchmark": f"lab shaking, alpha {r['alpha']:g}, N {r['n_rods']}, {r['rod_model']} "
                                 f"({r['n_vertices_per_rod']} vertices a rod): CPU-s per simulated s",
                    "rodwarp": f"{r['now_cpu_s_per_s']:.1f} (100 s: {r['now_cpu_s_per_s'] * 100 / 3600:.2f} h)",
                    "peer": (f"{rec['baseline']} ({r['before_state']}): {r['before_cpu_s_per_s']:.1f}"
                             if "before" in r else "n/a"),
                    "ratio": r.get("speedup")})
    return out


def plot(rec: dict, outdir) -> list[dict]:
    plt = common.pyplot()

    rows = rec["rows"]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    x = np.arange(len(rows))
    ax.bar(x + 0.2, [r["now_cpu_s_per_s"] for r in rows], 0.4, label="this code")
    if any("before" in r for r in rows):
        ax.bar(x - 0.2, [r.get("before_cpu_s_per_s", np.nan) for r in rows], 0.4,
               label=f"baseline {rec['baseline']}")
    ax.set_xticks(x, [f"alpha {r['alpha']:g}\nN {r['n_rods']}\n{r['rod_model']} {r['n_vertices_per_rod']}v"
                      for r in rows], fontsize=7)
    ax.set_yscale("log")
    ax.set_ylabel("CPU-s per simulated second of shaking")
    ax.axhline(72, color="k", ls=":", lw=1, label="100 s in 2 h")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=7)
    ax.set_title("excitation experiment (5 Hz, 25 mm, g 9.81), one core, median of runs", fontsize=9)
    fig.tight_layout()
    common.save_figure(fig, Path(outdir) / "lab_cost.png")  # atomic
    return [{"file": "lab_cost.png", "title": "CPU-s per simulated second of shaking at the paper's N",
             "reading": "Log scale; the dotted line is 100 s of shaking in two hours. In the fifth group the "
                        "baseline runs its own model of the case, 10 vertices a rod (the rule gives 3). Command "
                        "`RODWARP_BASELINE_PYTHON=... python -m benchmarks --full --only lab_cost`."}]
