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


#: the commit before issue 33's work: the 512^3 timing compares today's code with it too
PREVIOUS_COMMIT = "9d9e737"


def baseline_tree(commit: str = BASELINE_COMMIT) -> Path:
    """A copy of ``rodwarp/`` at ``commit``, extracted once per process."""
    d = Path(tempfile.gettempdir()) / f"rodwarp-baseline-{commit}"
    if not (d / "rodwarp" / "__init__.py").exists():
        d.mkdir(parents=True, exist_ok=True)
        arch = subprocess.run(["git", "archive", commit, "rodwarp"], cwd=common.ROOT, capture_output=True,
                              check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(d)], input=arch, check=True)
    return d


def segment_before(volume, spacing_x: float = 1.0, commit: str = BASELINE_COMMIT) -> dict:
    """Run the segmenter of ``commit`` on ``volume`` in a subprocess: {rods, contacts, time_s} or {error}."""
    from rodwarp.rodset import Contacts, RodSet

    script = _BASELINE_SCRIPT if commit == BASELINE_COMMIT else \
        _BASELINE_SCRIPT.replace("from rodwarp.segment import segment_volume", "from rodwarp.ct import segment_volume")
    with tempfile.TemporaryDirectory() as tmp:
        vin, vout = Path(tmp) / "vol.npy", Path(tmp) / "out.npz"
        np.save(vin, np.asarray(volume))
        env = dict(os.environ, PYTHONPATH=str(baseline_tree(commit)))
        p = subprocess.run([sys.executable, "-c", script, str(vin), str(vout)], capture_output=True,
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
            "flags": res.quality.get("flags", []), "shape": res.quality.get("shape"), "doubt": res.doubt}


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
        out = segment_after(case.volume, case.voxel_size)
        rec["after"] = score(case, out)
        if "rods" in out:
            rec["after"].update(_doubt_scores(case, out))
        if case.curved and "rods" in out:
            rec["cv_e"] = {"found": _cv_e(out["rods"]), "truth": _cv_e(case.truth),
                           **_cv_e_common(out["rods"], case)}
    return rec


def _doubt_scores(case, out) -> dict:
    """How the per-trace confidence sorts the traces: doubtful share of the matched and of the
    unmatched found traces, and the unexplained foreground."""
    from rodwarp.ct import match_polylines, match_rods

    d = out.get("doubt")
    if d is None:
        return {}
    m = (match_polylines if case.curved else match_rods)(out["rods"], case.truth)
    hit = np.zeros(out["rods"].n_rods, bool)
    hit[m.pairs[:, 0]] = True
    low = d.confidence < 0.7
    return {"doubtful_matched": float(low[hit].mean()) if hit.any() else None,
            "doubtful_unmatched": float(low[~hit].mean()) if (~hit).any() else None,
            "unexplained": float(d.unexplained_fraction)}


def _cv_e(rods, radius=None, box=None) -> float | None:
    """cv_e (the paper's sigma_e / mu_e) of a rod set, by default at its own default ball radius
    sqrt(d l) on the grid of its own bounding box."""
    from rodwarp.analysis import compute_fields, field_statistics

    if box is not None:
        rods = rods.copy()
        rods.box = np.asarray(box, float)
    st = field_statistics(compute_fields(rods, radius=radius, device="cpu"))
    return st.get("cv_e")


def _cv_e_common(found, case) -> dict:
    """cv_e of the traced and the true filaments on one grid (the scanned volume, the truth's
    default ball radius), and how far the truth's own cv_e moves when its bounding box (the
    default grid) grows by one voxel on every side: the measure's own resolution here."""
    truth = case.truth
    box = np.stack([np.full(3, -0.5), np.asarray(case.volume.shape[::-1], float) - 0.5])
    R = float(np.sqrt(2.0 * np.mean(truth.radii) * np.mean(truth.rod_lengths())))
    P = truth.points
    return {"found_common": _cv_e(found, R, box), "truth_common": _cv_e(truth, R, box),
            "truth_grown_1": _cv_e(truth, None, np.stack([P.min(0) - 1.0, P.max(0) + 1.0]))}


def _sweep_volume(radius, blur, seed):
    from rodwarp import ct

    shape = (128, 128, 128)
    truth = ct.scene_random_packing(shape, n_rods=30, radius=radius, aspect=48.0 / (2 * radius) + 0.0,
                                    seed=seed, max_attempts=200000)
    vol = ct.render_phantom(truth, shape, blur_sigma=blur, cnr=5.0, seed=seed)
    return truth, vol


#: the seeds of every case are drawn from this generator seed (the issue number), never picked
SEED_DRAW = 33


def drawn_seeds(n: int) -> list[int]:
    """The ``n`` case seeds the benchmark draws (the same first seeds for any ``n``)."""
    return [int(v) for v in np.random.default_rng(SEED_DRAW).integers(0, 2 ** 31, max(int(n), 1))]


def _task(args):
    name, seed = args
    return run_case(name, seed)


def _stats(vals, worst=min) -> dict | None:
    v = [x for x in vals if x is not None]
    return {"median": float(np.median(v)), "worst": float(worst(v)), "n": len(v)} if v else None


def run(quick: bool, device: str) -> dict:
    from concurrent.futures import ProcessPoolExecutor

    from rodwarp.ct import CASES

    seeds = drawn_seeds(3 if quick else 10)
    out: dict = {"title": TITLE, "baseline_commit": BASELINE_COMMIT, "seed_draw": SEED_DRAW, "seeds": seeds}
    tasks = [(name, s) for name in CASES for s in seeds]
    workers = max(1, min(2, os.cpu_count() or 1))
    with ProcessPoolExecutor(workers) as ex:  # scores do not depend on the load; times are per task
        recs = list(ex.map(_task, tasks))
    rows = []
    for name in CASES:
        rr = [r for r in recs if r["case"] == name]
        agg = {"case": name, "notes": rr[0]["notes"], "seeds": [r["seed"] for r in rr], "runs": rr}
        for side in ("before", "after"):
            agg[side] = {k: _stats([r[side].get(k) for r in rr], max if k == "time_s" else min)
                         for k in ("rod_f1", "contact_recall", "contact_precision", "time_s")}
            agg[side]["errors"] = sum("error" in r[side] for r in rr)
        if "cv_e" in rr[0]:
            rel = [abs(r["cv_e"]["found"] / r["cv_e"]["truth"] - 1.0) for r in rr
                   if r.get("cv_e") and r["cv_e"]["found"] and r["cv_e"]["truth"]]
            agg["cv_e_rel_error"] = {"median": float(np.median(rel)), "max": float(np.max(rel)), "n": len(rel)} \
                if rel else None
            for key, (x, y) in (("cv_e_rel_error_common", ("found_common", "truth_common")),
                                ("truth_cv_e_grid_shift", ("truth_grown_1", "truth"))):
                rel = [abs(r["cv_e"][x] / r["cv_e"][y] - 1.0) for r in rr
                       if r.get("cv_e") and r["cv_e"].get(x) and r["cv_e"].get(y)]
                agg[key] = {"median": float(np.median(rel)), "max": float(np.max(rel)), "n": len(rel)} \
                    if rel else None
        for k in ("doubtful_matched", "doubtful_unmatched", "unexplained"):
            v = [r["after"].get(k) for r in rr if r["after"].get(k) is not None]
            agg.setdefault("doubt", {})[k] = float(np.mean(v)) if v else None
        a, b = agg["after"]["rod_f1"], agg["before"]["rod_f1"]
        log(f"{name}: F1 median/worst before {b['median']:.3f}/{b['worst']:.3f}, after {a['median']:.3f}/"
            f"{a['worst']:.3f} over {len(rr)} seeds")
        rows.append(agg)
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

    out["real_scan"] = real_scan_qa(common.RESULTS)

    if not quick:
        from rodwarp import ct

        shape = (512, 512, 512)
        truth = ct.scene_random_packing(shape, n_rods=800, radius=3.0, aspect=30.0, seed=0, max_attempts=400000)
        vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=0)
        case = ScanCase(name="512", volume=vol, truth=truth)
        tb, ta, tp, sb, sa, sp = [], [], [], None, None, None
        for _ in range(3):  # alternate, so that load from other work hits all alike
            ob = segment_before(vol)
            tb.append(ob.get("time_s"))
            sb = score(case, ob)
            op = segment_before(vol, commit=PREVIOUS_COMMIT)
            tp.append(op.get("time_s"))
            sp = score(case, op)
            oa = segment_after(vol)
            ta.append(oa.get("time_s"))
            sa = score(case, oa)
        out["timing_512"] = {"n_rods": truth.n_rods, "before_s": common.spread(tb), "after_s": common.spread(ta),
                             "previous_s": common.spread(tp), "previous_commit": PREVIOUS_COMMIT,
                             "ratio": float(np.median(ta) / np.median(tb)),
                             "ratio_previous": float(np.median(ta) / np.median(tp)),
                             "ratios_previous": [float(a / p) for a, p in zip(ta, tp)],
                             "before": sb, "after": sa, "previous": sp}
        log(f"512^3: before {np.median(tb):.1f} s, previous {np.median(tp):.1f} s, after {np.median(ta):.1f} s")
    return out


#: the real scan segmented for its QA (docs and provenance: examples/data/README.md)
REAL_SCAN = "examples/data/pcl_scaffold_128.tif"


def real_scan_qa(results_dir=None) -> dict:
    """``rodwarp segment`` on the real micro-CT of PCL fibres (as curved filaments, in voxels):
    the counts, the doubtful filaments, the unexplained foreground, and its QA figures copied to
    ``results/segment_real_*.png``."""
    import shutil

    from rodwarp.ct import SegmentParams
    from rodwarp.ct import run_segment
    from rodwarp.ct.segment import doubt_kind

    src = common.ROOT / REAL_SCAN
    dest = Path(results_dir) if results_dir is not None else common.ROOT / "benchmarks" / "results"
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        summ = run_segment(src, voxel_size=1.0, units="voxel", out=Path(tmp) / "seg",
                           params=SegmentParams(shape="curved"))
        dt = time.perf_counter() - t
        for name in ("qa_confidence.png", "qa_projection.png", "qa_slices.png"):
            shutil.copyfile(Path(tmp) / "seg" / name, dest / f"segment_real_{name[3:]}")
    q = summ["quality"]
    conf = np.array([f["confidence"] for f in summ["filaments"]])
    reasons: dict = {}
    for f in summ["filaments"]:
        for why in f["doubts"]:
            key = doubt_kind(why)
            reasons[key] = reasons.get(key, 0) + 1
    radii = np.array([f["radius"] for f in summ["filaments"]])
    return {"file": REAL_SCAN,
            "foreground_explained": q.get("foreground_explained"),
            "traces_off_foreground": int(sum(any(w.startswith("axis off the foreground") for w in f["doubts"])
                                             for f in summ["filaments"])),
            "radius_quartiles_voxels": [float(v) for v in np.percentile(radii, [25, 50, 75])] if len(radii) else None,
            "time_s": dt, "n_filaments": summ["n_rods"], "n_contacts": summ["n_contacts"],
            "diameter_voxels": summ["diameter_voxels"], "mean_length_voxels": summ["mean_rod_length"],
            "confidence_quartiles": [float(v) for v in np.percentile(conf, [25, 50, 75])] if len(conf) else None,
            "doubtful": int(np.sum(conf < 0.7)), "doubt_reasons": reasons, "unexplained": q["unexplained"],
            "flags": q["flags"]}


def _cell(row: dict) -> str:
    if "error" in row:
        return f"error ({row['error'][:70]})"
    p, r = row.get("contact_precision"), row.get("contact_recall")
    s = f"F1 {row['rod_f1']:.2f}, contacts P/R {fmt(p) if p is not None else '-'} / {fmt(r) if r is not None else '-'}"
    if row.get("mean_centreline_error") is not None:
        s += f", error {row['mean_centreline_error']:.2f} vx"
    return s


def _med(agg: dict, key: str) -> str:
    v = agg.get(key)
    return "-" if v is None else f"{v['median']:.2f} (worst {v['worst']:.2f})"


def summary(rec: dict) -> list[dict]:
    rows = []
    n = len(rec.get("seeds", [])) or 1
    for c in rec["cases"]:
        b, a = c["before"], c["after"]
        cell = f"F1 {_med(a, 'rod_f1')}, contact recall {_med(a, 'contact_recall')}"
        if c.get("cv_e_rel_error"):
            cell += f", cv_e off by {100 * c['cv_e_rel_error']['median']:.0f}% (max {100 * c['cv_e_rel_error']['max']:.0f}%)"
            if c.get("cv_e_rel_error_common") and c.get("truth_cv_e_grid_shift"):
                cc, g = c["cv_e_rel_error_common"], c["truth_cv_e_grid_shift"]
                cell += (f"; on one grid {100 * cc['median']:.0f}% (max {100 * cc['max']:.0f}%); the truth's own "
                         f"cv_e moves {100 * g['median']:.0f}% (max {100 * g['max']:.0f}%) when its grid grows "
                         f"1 voxel")
        d = c.get("doubt") or {}
        if d.get("doubtful_unmatched") is not None and d.get("doubtful_matched") is not None:
            cell += (f", doubtful: {100 * d['doubtful_unmatched']:.0f}% of unmatched / "
                     f"{100 * d['doubtful_matched']:.0f}% of matched traces")
        if a.get("errors"):
            cell += f", {a['errors']} errors"
        ratio = (f"{a['time_s']['median'] / b['time_s']['median']:.2f}x time"
                 if a.get("time_s") and b.get("time_s") else None)
        rows.append({"benchmark": f"{c['case']}: {c['notes']} (median and worst of {n} drawn seeds)",
                     "rodwarp": cell,
                     "peer": f"before ({rec['baseline_commit']}): F1 {_med(b, 'rod_f1')}, contact recall "
                             f"{_med(b, 'contact_recall')}" + (f", {b['errors']} errors" if b.get("errors") else ""),
                     "ratio": ratio})
    if rec.get("real_scan"):
        r = rec["real_scan"]
        u = r["unexplained"]
        rows.append({"benchmark": f"real micro-CT of PCL fibres ({r['file']}, 128^3): QA (segment_real_*.png)",
                     "rodwarp": f"{r['n_filaments']} filaments, {r['doubtful']} doubtful (confidence < 0.7), "
                                f"unexplained foreground {100 * u['fraction']:.1f}% in {u['regions']} regions"
                                + (f", explained {100 * r['foreground_explained']:.1f}%"
                                   if r.get("foreground_explained") is not None else ""),
                     "peer": "no truth: the QA shows where the trace is unsure", "ratio": None})
    if "timing_512" in rec:
        t = rec["timing_512"]
        rows.append({"benchmark": f"512^3, {t['n_rods']} rods (CNR 5, blur 1): time",
                     "rodwarp": f"{fmt(t['after_s']['median'])} s, F1 {t['after']['rod_f1']:.3f}",
                     "peer": f"before {fmt(t['before_s']['median'])} s, F1 {t['before']['rod_f1']:.3f}",
                     "ratio": f"{t['ratio']:.2f}x time"})
        if "previous_s" in t:
            rows.append({"benchmark": f"512^3, {t['n_rods']} rods: today against the previous commit "
                                      f"({t['previous_commit']}), alternated",
                         "rodwarp": f"{fmt(t['after_s']['median'])} s, F1 {t['after']['rod_f1']:.3f}",
                         "peer": f"previous {fmt(t['previous_s']['median'])} s, F1 {t['previous']['rod_f1']:.3f}",
                         "ratio": f"{t['ratio_previous']:.2f}x time"})
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
    for side, dx, col in (("before", -0.2, "C7"), ("after", 0.2, "C0")):
        med = np.array([c[side]["rod_f1"]["median"] for c in rec["cases"]])
        worst = np.array([c[side]["rod_f1"]["worst"] for c in rec["cases"]])
        ax.bar(x + dx, med, 0.4, color=col, label=f"{side}: median")
        ax.errorbar(x + dx, med, yerr=[med - worst, np.zeros_like(med)], fmt="none", ecolor="k", capsize=2,
                    lw=0.8, label="worst seed" if side == "after" else None)
    ax.set_xticks(x, names, rotation=35, ha="right", fontsize=8)
    ax.set_ylabel("rod / filament F1")
    ax.axhline(0.95, color="k", lw=0.6, ls=":")
    ax.legend(fontsize=8)
    ax.set_title(f"Realistic-scan phantoms: rod F1 before and after, median and worst of "
                 f"{len(rec.get('seeds', [])) or 1} drawn seeds")
    fig.tight_layout()
    f2 = common.save_figure(fig, outdir / "segment_scans_cases.png")
    return [{"file": f1, "title": "rod F1 against radius and blur, before and after",
             "reading": "dotted line: the 0.95 target; grey: the baseline commit, blue: today"},
            {"file": f2, "title": "rod F1 on every realistic-scan case, before and after",
             "reading": "each pair of bars is one phantom case, median over the drawn seeds, the whisker down to the worst "
                        "seed (benchmarks/RESULTS.md table for contacts)"}]


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
