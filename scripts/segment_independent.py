"""Segmentation scored on the second, independent phantom generator (issue 50's benchmark table).

For each regime (touching bundles of thin rods with crossing rods; wire tangles) and radius
(1.5, 2 and 3 voxels), the script draws ``--seeds`` seeds itself (a fresh entropy unless
``--entropy`` repeats a draw) and does the following for each seed:
- renders the scene with :mod:`rodwarp.testing.ct_generator`, which shares no code with
  ``rodwarp phantom``;
- segments it with ``rodwarp.ct.segment_volume`` at its defaults;
- scores rods (bundles: ``match_rods``; wires: ``match_polylines``) and contacts
  (``score_contacts``, true contacts from the true geometry: the generator's touching pairs are
  at gap 0 and every other pair at least a voxel apart).

It writes ``benchmarks/results/segment_independent.{json,md}``: per regime and radius, the median
and worst rod F1 and contact recall over the seeds, with every seed's row and the drawn seeds.

    python scripts/segment_independent.py [--seeds 10] [--entropy N] [--label before]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
RADII = (1.5, 2.0, 3.0)


def _truth(scene):
    from rodwarp.rodset import RodSet

    return RodSet.from_polylines(scene.polylines, radii=[float(scene.radius[scene.rod == k][0])
                                                         for k in range(scene.n_rods)], units="voxel")


def run_one(regime: str, radius: float, seed: int) -> dict:
    from rodwarp.ct import match_polylines, match_rods, score_contacts, segment_volume
    from rodwarp.errors import RodwarpError
    from rodwarp.testing import ct_generator as g

    if regime == "bundles":
        scene = g.touching_bundles(shape=(96, 128, 128), radius=radius, length=28.0 * radius + 14.0, seed=seed)
    else:
        scene = g.wire_tangle(shape=(96, 128, 128), radius=radius, seed=seed)
    vol = g.render(scene, seed=seed)
    truth = _truth(scene)
    t0 = time.perf_counter()
    try:
        res = segment_volume(vol)
    except RodwarpError as e:
        return {"regime": regime, "radius": radius, "seed": seed, "error": str(e), "rod_f1": 0.0,
                "contact_recall": 0.0 if scene.contacts else None}
    wall = time.perf_counter() - t0
    m = match_rods(res.rods, truth) if regime == "bundles" else match_polylines(res.rods, truth)
    row = {"regime": regime, "radius": radius, "seed": seed, "n_true": int(m.n_true), "n_found": int(m.n_found),
           "rod_f1": float(m.f1), "rod_precision": float(m.precision), "rod_recall": float(m.recall),
           "segment_s": wall, "true_contacts": len(scene.contacts)}
    if scene.contacts:
        c = score_contacts(res.contacts, truth, m)
        row.update(contact_recall=float(c.recall) if c.tp + c.fn else None,
                   contact_precision=float(c.precision) if c.tp + c.fp else None)
    else:
        row.update(contact_recall=None, contact_precision=None)
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--entropy", type=int, default=None, help="repeat an earlier draw of seeds")
    ap.add_argument("--label", default="before", help="the code state scored (before, after)")
    ap.add_argument("--regimes", default="bundles,wires")
    a = ap.parse_args()
    ss = np.random.SeedSequence(a.entropy)
    seeds = [int(s) for s in ss.generate_state(a.seeds, dtype=np.uint32)]
    rows = []
    for regime in a.regimes.split(","):
        for r in RADII:
            for s in seeds:
                row = run_one(regime, r, s)
                rows.append(row)
                print(json.dumps(row), flush=True)
    summary = []
    for regime in a.regimes.split(","):
        for r in RADII:
            sel = [x for x in rows if x["regime"] == regime and x["radius"] == r]
            f1 = [x["rod_f1"] for x in sel]
            cr = [x["contact_recall"] for x in sel if x.get("contact_recall") is not None]
            summary.append({"regime": regime, "radius": r, "n": len(sel), "rod_f1_median": statistics.median(f1),
                            "rod_f1_worst": min(f1), "contact_recall_median": statistics.median(cr) if cr else None,
                            "contact_recall_worst": min(cr) if cr else None,
                            "segment_s_median": statistics.median(x.get("segment_s", 0.0) for x in sel)})
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "")
    out = {"label": a.label, "commit": head, "entropy": ss.entropy, "seeds": seeds, "summary": summary, "rows": rows,
           "cpu": cpu, "python": platform.python_version(),
           "command": f"python scripts/segment_independent.py --seeds {a.seeds} --entropy {ss.entropy}"}
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"segment_independent_{a.label}.json").write_text(json.dumps(out, indent=1))
    lines = [f"# Segmentation on the independent generator ({a.label}, {head})", "",
             f"{cpu}; `{out['command']}`; seeds drawn by the script: {seeds}.",
             "Scenes: `rodwarp.testing.ct_generator` (96 x 128 x 128 voxels), segmented by "
             "`rodwarp.ct.segment_volume` at its defaults.", "",
             "| regime | radius (voxels) | seeds | rod F1 median | worst | contact recall median | worst | "
             "segment (s) |", "|---|---|---|---|---|---|---|---|"]
    fmt = lambda v: "-" if v is None else f"{v:.3f}"  # noqa: E731
    for s in summary:
        lines.append(f"| {s['regime']} | {s['radius']:g} | {s['n']} | {fmt(s['rod_f1_median'])} | "
                     f"{fmt(s['rod_f1_worst'])} | {fmt(s['contact_recall_median'])} | "
                     f"{fmt(s['contact_recall_worst'])} | {s['segment_s_median']:.1f} |")
    (OUT / f"segment_independent_{a.label}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
