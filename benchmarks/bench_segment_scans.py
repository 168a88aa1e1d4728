"""CT segmentation of realistic scans, before and after: every phantom case of
``rodwarp.ct`` segmented by today's code and by the code at the baseline commit
(the segmenter before field-of-view masks, background correction, anisotropic voxels, per-rod
radii, bundles and curved filaments), on the same machine in the same run; rod F1 against
radius and against blur for both; and, in full mode, the 512^3 / 800-rod timing for both.

The baseline runs in a subprocess on a copy of ``rodwarp/`` taken from git at
``BASELINE_COMMIT`` (``git archive``), fed the same volumes; scoring is the same for both
(``rodwarp.ct.match_rods`` for straight truth, ``rodwarp.ct.match_polylines``
for curved truth, ``score_contacts`` through either matching).  The baseline knows one
isotropic voxel size only: its coordinates are scaled by the x voxel size.

Command line for one case: ``python -m benchmarks.bench_segment_scans CASE [--before]``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import common
from benchmarks.common import fmt, log

NAME = "segment_scans"
TITLE = "CT segmentation of realistic scans (phantoms with truth): before (baseline commit) and after"
BASELINE_COMMIT = "fa4b7db"

RADII = [1.5, 2.0, 2.5, 3.0, 4.0, 5.0]
BLURS = [0.5, 1.0, 1.5, 2.0, 2.5]

_BASELINE_SCRIPT = r"""
import json, sys, time
import numpy as np
from rodwarp.segment import segment_volume  # the baseline tree's layout (before issue 16)
from rodwarp.errors import RodwarpError
vol = np.load(sys.argv[1])
t = time.perf_counter()
try:
    res = segment_volume(vol)
except RodwarpError as e:
    print(json.dumps({"error": str(e), "time_s": time.perf_counter() - t}))
    sys.exit(0)
dt = time.perf_counter() - t
r = res.rods
c = res.contacts
np.savez(sys.argv[2], points=r.points, offsets=r.offsets, radii=r.radii, ci=c.rod_i, cj=c.rod_j,
         cp=c.point, cg=c.gap)
print(json.dumps({"time_s": dt, "n_rods": int(r.n_rods), "n_contacts": int(len(c))}))
"""


def baseline_tree() -> Path:
    """A copy of ``rodwarp/`` at the baseline commit, extracted once per process."""
    d = Path(tempfile.gettempdir()) / f"rodwarp-baseline-{BASELINE_COMMIT}"
    if not (d / "rodwarp" / "segment.py").exists():
        d.mkdir(parents=True, exist_ok=True)
        arch = subprocess.run(["git", "archive", BASELINE_COMMIT, "rodwarp"], cwd=common.ROOT, capture_output=True,
                              check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(d)], input=arch, check=True)
    return d


def segment_before(volume, spacing_x: float = 1.0) -> dict:
    """Run the baseline segmenter on ``volume`` in a subprocess: {rods, contacts, time_s} or {error}."""
    from rodwarp.rodset import Contacts, RodSet

    with tempfile.TemporaryDirectory() as tmp:
        vin, vout = Path(tmp) / "vol.npy", Path(tmp) / "out.npz"
        np.save(vin, np.asarray(volume))
        env = dict(os.environ, PYTHONPATH=str(baseline_tree()))
        p = subprocess.run([sys.executable, "-c", _BASELINE_SCRIPT, str(vin), str(vout)], capture_output=True,
                           text=True, env=env, cwd=tmp)
        if p.returncode != 0:
            return {"error": "baseline crashed: " + (p.stderr.strip().splitlines() or ["?"])[-1]}
        info = json.loads(p.stdout.strip().splitlines()[-1])
        if "error" in info:
            return info
        z = np.load(vout)
        rods = RodSet(z["points"] * spacing_x, z["offsets"], z["radii"] * spacing_x, units="voxel")
        con = Contacts(z["ci"], z["cj"], z["cp"] * spacing_x, z["cg"] * spacing_x)
        return {"rods": rods, "contacts": con, "time_s": info["time_s"]}


def segment_after(volume, voxel_size=(1.0, 1.0, 1.0)) -> dict:
    from rodwarp.errors import RodwarpError
    from rodwarp.ct import segment_volume

    t = time.perf_counter()
    try:
        res = segment_volume(volume, voxel_size=voxel_size)
    except RodwarpError as e:
        return {"error": str(e), "time_s": time.perf_counter() - t}
    return {"rods": res.rods, "contacts": res.contacts, "time_s": time.perf_counter() - t,
            "flags": res.quality.get("flags", []), "shape": res.quality.get("shape")}


def score(case, out: dict) -> dict:
    """Rod (or filament) F1, contact precision / recall, centreline error, self-contacts."""
    from rodwarp.ct import match_rods, score_contacts
    from rodwarp.ct import match_polylines

    row = {"time_s": out.get("time_s")}
    if "error" in out:
        row.update(error=out["error"], rod_f1=0.0, contact_precision=None, contact_recall=None)
        return row
    from rodwarp.ct import scored_subset

    shape_xyz = np.asarray(case.volume.shape[::-1], float) * np.asarray(case.voxel_size[::-1], float)
    found, con = scored_subset(out["rods"], out["contacts"], shape_xyz, case.face_margin)
    truth, tc = scored_subset(case.truth, case.truth.contacts, shape_xyz, case.face_margin)
    truth.contacts = tc
    if case.curved:
        m = match_polylines(found, truth)
    else:
        m = match_rods(found, truth)
    c = score_contacts(con, truth, m)
    n_true_c = c.tp + c.fn
    row.update(n_found=int(m.n_found), n_true=int(m.n_true), rod_f1=float(m.f1), rod_precision=float(m.precision),
               rod_recall=float(m.recall), contact_precision=float(c.precision) if c.tp + c.fp else None,
               contact_recall=float(c.recall) if n_true_c else None, contacts_found=int(len(con)),
               contacts_true=int(n_true_c),
               mean_centreline_error=float(np.mean(m.mean_distance)) if len(m.pairs) else None)
    if "flags" in out:
        row["flags"] = out["flags"]
        row["shape"] = out.get("shape")
    return row


def run_case(name: str, seed: int = 0, before: bool = True, after: bool = True) -> dict:
    from rodwarp.ct import make_case

    case = make_case(name, seed)
    rec = {"case": name, "notes": case.notes, "seed": seed, "shape": list(case.volume.shape),
           "n_true": case.truth.n_rods}
    if before:
        rec["before"] = score(case, segment_before(case.volume, spacing_x=case.voxel_size[2]))
    if after:
        rec["after"] = score(case, segment_after(case.volume, case.voxel_size))
    return rec


def _sweep_volume(radius, blur, seed):
    from rodwarp import ct

    shape = (128, 128, 128)
    truth = ct.scene_random_packing(shape, n_rods=30, radius=radius, aspect=48.0 / (2 * radius) + 0.0,
                                    seed=seed, max_attempts=200000)
    vol = ct.render_phantom(truth, shape, blur_sigma=blur, cnr=5.0, seed=seed)
    return truth, vol


def run(quick: bool, device: str) -> dict:
    from rodwarp.ct import CASES

    out: dict = {"title": TITLE, "baseline_commit": BASELINE_COMMIT}
    rows = []
    for name in CASES:
        rec = run_case(name, 0)
        b, a = rec["before"], rec["after"]
        log(f"{name}: before F1 {b['rod_f1']:.3f} {b.get('error', '')[:60]} | after F1 {a['rod_f1']:.3f} "
            f"{a.get('error', '')[:60]} ({fmt(b['time_s'])} s / {fmt(a['time_s'])} s)")
        rows.append(rec)
    out["cases"] = rows

    from rodwarp.ct import ScanCase

    sweep = []
    for kind, values in (("radius", RADII), ("blur", BLURS)):
        for v in values:
            r, bl = (v, 1.0) if kind == "radius" else (2.0, v)
            truth, vol = _sweep_volume(r, bl, 1)
            case = ScanCase(name=f"{kind}={v}", volume=vol, truth=truth)
            b = score(case, segment_before(vol))
            a = score(case, segment_after(vol))
            log(f"sweep {kind}={v}: F1 before {b['rod_f1']:.3f}, after {a['rod_f1']:.3f}")
            sweep.append({"kind": kind, "value": v, "radius": r, "blur": bl, "before": b, "after": a})
    out["sweep"] = sweep

    if not quick:
        from rodwarp import ct

        shape = (512, 512, 512)
        truth = ct.scene_random_packing(shape, n_rods=800, radius=3.0, aspect=30.0, seed=0, max_attempts=400000)
        vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=0)
        case = ScanCase(name="512", volume=vol, truth=truth)
        tb, ta, sb, sa = [], [], None, None
        for _ in range(2):  # alternate, so that load from other work hits both alike
            ob = segment_before(vol)
            tb.append(ob.get("time_s"))
            sb = score(case, ob)
            oa = segment_after(vol)
            ta.append(oa.get("time_s"))
            sa = score(case, oa)
        out["timing_512"] = {"n_rods": truth.n_rods, "before_s": common.spread(tb), "after_s": common.spread(ta),
                             "ratio": float(np.median(ta) / np.median(tb)), "before": sb, "after": sa}
        log(f"512^3: before {np.median(tb):.1f} s, after {np.median(ta):.1f} s")
    return out


def _cell(row: dict) -> str:
    if "error" in row:
        return f"error ({row['error'][:70]})"
    p, r = row.get("contact_precision"), row.get("contact_recall")
    s = f"F1 {row['rod_f1']:.2f}, contacts P/R {fmt(p) if p is not None else '-'} / {fmt(r) if r is not None else '-'}"
    if row.get("mean_centreline_error") is not None:
        s += f", error {row['mean_centreline_error']:.2f} vx"
    return s


def summary(rec: dict) -> list[dict]:
    rows = []
    for c in rec["cases"]:
        b, a = c["before"], c["after"]
        ratio = (f"{a['time_s'] / b['time_s']:.2f}x time" if b.get("time_s") and a.get("time_s") and "error" not in b
                 else None)
        rows.append({"benchmark": f"{c['case']}: {c['notes']}", "rodwarp": _cell(a),
                     "peer": f"before ({rec['baseline_commit']}): {_cell(b)}", "ratio": ratio})
    if "timing_512" in rec:
        t = rec["timing_512"]
        rows.append({"benchmark": f"512^3, {t['n_rods']} rods (CNR 5, blur 1): time",
                     "rodwarp": f"{fmt(t['after_s']['median'])} s, F1 {t['after']['rod_f1']:.3f}",
                     "peer": f"before {fmt(t['before_s']['median'])} s, F1 {t['before']['rod_f1']:.3f}",
                     "ratio": f"{t['ratio']:.2f}x time"})
    for kind in ("radius", "blur"):
        ss = [s for s in rec["sweep"] if s["kind"] == kind]
        rows.append({"benchmark": f"rod F1 against {kind} (128^3, 30 rods, CNR 5"
                                  f"{', blur 1' if kind == 'radius' else ', radius 2'})",
                     "rodwarp": ", ".join(f"{s['value']}: {s['after']['rod_f1']:.2f}" for s in ss),
                     "peer": "before: " + ", ".join(f"{s['value']}: {s['before']['rod_f1']:.2f}" for s in ss),
                     "ratio": None})
    return rows


def plot(rec: dict, outdir) -> list[dict]:
    plt = common.pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, kind, lab in ((axes[0], "radius", "rod radius (voxels), blur 1"),
                          (axes[1], "blur", "blur sigma (voxels), radius 2")):
        ss = [s for s in rec["sweep"] if s["kind"] == kind]
        x = [s["value"] for s in ss]
        ax.plot(x, [s["before"]["rod_f1"] for s in ss], "o--", color="C7", label=f"before ({rec['baseline_commit']})")
        ax.plot(x, [s["after"]["rod_f1"] for s in ss], "o-", color="C0", label="after")
        ax.set_xlabel(lab)
        ax.set_ylabel("rod F1")
        ax.set_ylim(-0.03, 1.03)
        ax.axhline(0.95, color="k", lw=0.6, ls=":")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Rod F1 against radius and blur (128^3, 30 straight rods, CNR 5): before and after")
    f1 = common.save_figure(fig, outdir / "segment_scans_f1.png")
    fig, ax = plt.subplots(figsize=(10, 4.4))
    names = [c["case"] for c in rec["cases"]]
    x = np.arange(len(names))
    ax.bar(x - 0.2, [c["before"]["rod_f1"] for c in rec["cases"]], 0.4, color="C7", label="before")
    ax.bar(x + 0.2, [c["after"]["rod_f1"] for c in rec["cases"]], 0.4, color="C0", label="after")
    ax.set_xticks(x, names, rotation=35, ha="right", fontsize=8)
    ax.set_ylabel("rod / filament F1")
    ax.axhline(0.95, color="k", lw=0.6, ls=":")
    ax.legend(fontsize=8)
    ax.set_title("Realistic-scan phantoms: rod F1 before and after")
    fig.tight_layout()
    f2 = common.save_figure(fig, outdir / "segment_scans_cases.png")
    return [{"file": f1, "title": "rod F1 against radius and blur, before and after",
             "reading": "dotted line: the 0.95 target; grey: the baseline commit, blue: today"},
            {"file": f2, "title": "rod F1 on every realistic-scan case, before and after",
             "reading": "each pair of bars is one phantom case (benchmarks/RESULTS.md table for contacts)"}]


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--before", action="store_true", help="baseline only")
    ap.add_argument("--after", action="store_true", help="today's code only")
    a = ap.parse_args()
    for nm in a.cases:
        r = run_case(nm, 0, before=not a.after, after=not a.before)
        print(json.dumps(r, default=str), flush=True)
