"""Accuracy of the protocol against the time step: final Z and f for alpha = 50 and 200 at the
default step and at default / 3 and default / 10 (1 s + 1 s). Wraps
``scripts/protocol_dt_accuracy.py``; finished points under ``runs/dt_accuracy`` are reused."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

from benchmarks import common

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "runs" / "dt_accuracy"
ARGS = ["--entangle-duration", "1", "--duration", "1", "--workers", "2", "--out", str(RUNS)]


def run(quick: bool, device: str) -> dict:
    sys.path.insert(0, str(ROOT / "scripts"))
    import protocol_dt_accuracy

    protocol_dt_accuracy.main(ARGS)
    meta = json.loads((RUNS / "dt_accuracy.json").read_text())
    shutil.copy(RUNS / "dt_accuracy.png", common.RESULTS / "protocol_dt.png")
    return {"title": "Protocol outcome against the time step (alpha = 50, 200)",
            "script_command": "python scripts/protocol_dt_accuracy.py " + " ".join(ARGS[:-2] + ["--out", "runs/dt_accuracy"]),
            **meta}


def summary(rec: dict) -> list[dict]:
    rows = []
    for a in sorted({r["alpha"] for r in rec["rows"]}):
        sel = sorted((r for r in rec["rows"] if r["alpha"] == a), key=lambda r: r["divisor"])
        ref = sel[-1]
        for r in sel:
            rows.append({"benchmark": f"alpha = {a:g}, dt = default / {r['divisor']:g} ({r['dt']:.3g} s)",
                         "rodwarp": f"Z = {r['Z']:.2f}, f = {r['f']:.3f}, wall {r['wall_time_s']:.0f} s",
                         "peer": f"dt / {ref['divisor']:g}: Z = {ref['Z']:.2f}, f = {ref['f']:.3f}",
                         "ratio": r["Z"] / ref["Z"] if ref["Z"] else None})
    return rows


def plot(rec: dict, outdir) -> list[dict]:
    return [{"file": "protocol_dt.png", "title": "Protocol outcome vs time step",
             "reading": "Final Z (left), f (middle) and wall time (right) against dt; dashed lines mark the default. "
                        "The ratio column is Z at each step over Z at the smallest step."}]
