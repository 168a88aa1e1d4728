"""Segmentation cost on the 512^3 benchmark volume: today's code against 7aadaac, same run.

Issue 50, item 5 ("the 512^3 benchmark no slower than today"): the volume is built exactly as
``benchmarks/bench_segment_scans.py`` builds its 512^3 timing case::

    truth = ct.scene_random_packing((512, 512, 512), n_rods=800, radius=3.0, aspect=30.0,
                                    seed=0, max_attempts=400000)
    vol = ct.render_phantom(truth, (512, 512, 512), blur_sigma=1.0, cnr=5.0, seed=0)

It is built once (by this checkout's ``rodwarp``) and saved to a temporary ``.npy``.  Each
segmentation runs in a fresh subprocess with ``PYTHONPATH`` set to one code tree, so that tree's
``rodwarp`` is imported (the subprocess reports ``rodwarp.__file__``; the parent checks it lies
in that tree): ``rodwarp.ct.segment_volume(np.load(path))`` at its defaults, timed alone with
``time.perf_counter`` (loading and saving excluded).  The rods and contacts come back in an
``.npz`` and the parent scores both trees' output against the truth with today's
``rodwarp.ct.match_rods`` and ``score_contacts`` (the whole volume, as the benchmark does).

The trees alternate, before then after, ``--repeats`` pairs; each pair gives a ratio
after / before, so load from other work on the machine hits both alike as far as it can.

    git worktree add /tmp/wt_before_cost 7aadaac     # or any worktree at 7aadaac
    python scripts/segment_cost_512.py --before-tree /tmp/wt_before_cost --repeats 3

``--after-tree`` defaults to this checkout; where others edit ``rodwarp/`` in it while this runs,
pass a worktree at ``HEAD`` instead (``git worktree add --detach /tmp/wt_after_cost HEAD``) so
every "after" segmentation runs the same committed code.  The volume is built and the scores
computed by this checkout's ``rodwarp``.

Writes ``benchmarks/results/segment_cost_512.{json,md}`` (``--out`` changes the stem).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
BEFORE_COMMIT = "7aadaac"
SHAPE = (512, 512, 512)

_CHILD = r"""
import json, sys, time
import numpy as np
import rodwarp
from rodwarp.ct import segment_volume
vol = np.load(sys.argv[1])
t = time.perf_counter()
res = segment_volume(vol)
dt = time.perf_counter() - t
r, c = res.rods, res.contacts
np.savez(sys.argv[2], points=r.points, offsets=r.offsets, radii=r.radii, ci=c.rod_i, cj=c.rod_j,
         cp=c.point, cg=c.gap)
print(json.dumps({"time_s": dt, "n_rods": int(r.n_rods), "n_contacts": int(len(c)),
                  "rodwarp_file": rodwarp.__file__}))
"""


def _git(args, cwd) -> str:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "?"


def _mem_gib() -> dict:
    out = {}
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            k, v = line.split(":", 1)
            if k in ("MemTotal", "MemAvailable"):
                out[k] = round(int(v.split()[0]) / 2**20, 1)
    except OSError:
        pass
    return out


def segment_in(tree: Path, vol_path: Path, tmp: Path, tag: str) -> dict:
    """Segment the saved volume with the ``rodwarp`` of ``tree`` in a fresh subprocess."""
    out = tmp / f"{tag}.npz"
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", _CHILD, str(vol_path), str(out)], capture_output=True,
                       text=True, env=env, cwd=str(tmp))
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"segmentation in {tree} failed:\n{p.stderr[-3000:]}")
    info = json.loads(p.stdout.strip().splitlines()[-1])
    f = Path(info["rodwarp_file"]).resolve()
    if Path(tree).resolve() not in f.parents:
        raise RuntimeError(f"subprocess imported {f}, not the rodwarp of {tree}")
    info["subprocess_wall_s"] = wall
    info["npz"] = out
    return info


def score(info: dict, truth) -> dict:
    """Rod F1 and contact F1 of one segmentation against the truth (today's scoring)."""
    from rodwarp.ct import match_rods, score_contacts
    from rodwarp.rodset import Contacts, RodSet

    z = np.load(info["npz"])
    rods = RodSet(z["points"], z["offsets"], z["radii"], units="voxel")
    con = Contacts(z["ci"], z["cj"], z["cp"], z["cg"])
    m = match_rods(rods, truth)
    c = score_contacts(con, truth, m)
    return {"n_found": int(m.n_found), "n_true": int(m.n_true), "rod_f1": float(m.f1),
            "rod_precision": float(m.precision), "rod_recall": float(m.recall),
            "contacts_found": int(len(con)), "contacts_true": int(c.tp + c.fn), "contact_tp": int(c.tp),
            "contact_fp": int(c.fp), "contact_fn": int(c.fn), "contact_precision": float(c.precision),
            "contact_recall": float(c.recall), "contact_f1": float(c.f1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before-tree", default=None,
                    help=f"a checkout (git worktree) at {BEFORE_COMMIT}; default: /tmp/wt_before_cost, "
                         "created with `git worktree add` when missing")
    ap.add_argument("--after-tree", default=str(ROOT), help="today's tree (default: this checkout)")
    ap.add_argument("--repeats", type=int, default=3, help="before/after pairs (default 3)")
    ap.add_argument("--out", default=str(OUT / "segment_cost_512"), help="output stem (.json, .md added)")
    a = ap.parse_args(argv)

    script = Path(sys.argv[0]).resolve()
    script = str(script.relative_to(ROOT)) if script.is_relative_to(ROOT) else sys.argv[0]
    cmd = "python " + " ".join([script, *(argv if argv is not None else sys.argv[1:])])
    before = Path(a.before_tree) if a.before_tree else Path("/tmp/wt_before_cost")
    if not (before / "rodwarp" / "__init__.py").exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(before), BEFORE_COMMIT], cwd=ROOT, check=True)
    after = Path(a.after_tree)
    before_head = _git(["rev-parse", "HEAD"], before)
    if not before_head.startswith(_git(["rev-parse", BEFORE_COMMIT], ROOT)[:12]):
        raise SystemExit(f"{before} is at {before_head}, not {BEFORE_COMMIT}")
    before_dirty = _git(["status", "--porcelain", "--", "rodwarp"], before)
    after_head = _git(["rev-parse", "HEAD"], after)
    after_dirty = _git(["status", "--porcelain", "--", "rodwarp"], after)

    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    load0 = os.getloadavg()
    t_all = time.perf_counter()

    from rodwarp import ct

    t = time.perf_counter()
    truth = ct.scene_random_packing(SHAPE, n_rods=800, radius=3.0, aspect=30.0, seed=0, max_attempts=400000)
    vol = ct.render_phantom(truth, SHAPE, blur_sigma=1.0, cnr=5.0, seed=0)
    t_build = time.perf_counter() - t
    print(f"volume {vol.shape} {vol.dtype}, {truth.n_rods} rods, built in {t_build:.1f} s", flush=True)

    pairs = []
    with tempfile.TemporaryDirectory(prefix="segcost512_") as tmp:
        tmp = Path(tmp)
        vol_path = tmp / "vol.npy"
        np.save(vol_path, vol)
        del vol
        for k in range(a.repeats):
            row = {"pair": k + 1}
            for side, tree in (("before", before), ("after", after)):
                la = os.getloadavg()[0]
                info = segment_in(tree, vol_path, tmp, f"{side}{k}")
                sc = score(info, truth)
                row[side] = {"time_s": info["time_s"], "subprocess_wall_s": info["subprocess_wall_s"],
                             "n_rods": info["n_rods"], "n_contacts": info["n_contacts"],
                             "rodwarp_file": info["rodwarp_file"], "load1_at_start": la, **sc}
                print(f"pair {k + 1} {side}: {info['time_s']:.1f} s, {info['n_rods']} rods, "
                      f"F1 {sc['rod_f1']:.3f}, contact F1 {sc['contact_f1']:.3f} ({info['rodwarp_file']})",
                      flush=True)
            row["ratio_after_over_before"] = row["after"]["time_s"] / row["before"]["time_s"]
            print(f"pair {k + 1}: ratio after/before {row['ratio_after_over_before']:.3f}", flush=True)
            pairs.append(row)

    load1 = os.getloadavg()
    tb = [p["before"]["time_s"] for p in pairs]
    ta = [p["after"]["time_s"] for p in pairs]
    ratios = [p["ratio_after_over_before"] for p in pairs]
    import numpy  # noqa: F401  (version below)

    rec = {
        "what": "rodwarp.ct.segment_volume on the 512^3 / 800-rod benchmark volume "
                "(benchmarks/bench_segment_scans.py), today's code against 7aadaac, alternating in one run",
        "command": cmd,
        "started_utc": started,
        "total_s": time.perf_counter() - t_all,
        "volume": {"shape": list(SHAPE), "n_rods_true": int(truth.n_rods), "contacts_true": pairs[0]["after"]["contacts_true"],
                   "build_s": t_build,
                   "recipe": "ct.scene_random_packing((512,512,512), n_rods=800, radius=3.0, aspect=30.0, seed=0, "
                             "max_attempts=400000); ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=0)"},
        "before": {"commit": before_head, "tree": str(before), "rodwarp_dirty": before_dirty or None},
        "after": {"commit": after_head, "tree": str(after), "rodwarp_dirty": after_dirty or None},
        "machine": {"cpu_model": _cpu_model(), "cpu_count": os.cpu_count(), "memory_gib": _mem_gib(),
                    "python": platform.python_version(), "numpy": np.__version__, "platform": platform.platform(),
                    "thread_env": {k: os.environ[k] for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                                               "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
                                   if k in os.environ}},
        "loadavg_start": list(load0), "loadavg_end": list(load1),
        "repeats": len(pairs),
        "pairs": pairs,
        "before_median_s": statistics.median(tb), "after_median_s": statistics.median(ta),
        "ratio_median": statistics.median(ratios), "ratio_of_medians": statistics.median(ta) / statistics.median(tb),
        "timing": "segment_volume call only (time.perf_counter in the subprocess); volume loading, imports and "
                  "saving excluded; scoring: today's match_rods / score_contacts on the whole volume",
    }
    stem = Path(a.out)
    stem.parent.mkdir(parents=True, exist_ok=True)
    stem.with_suffix(".json").write_text(json.dumps(rec, indent=1) + "\n")
    stem.with_suffix(".md").write_text(markdown(rec))
    print(f"median ratio after/before {rec['ratio_median']:.3f} over {len(pairs)} pairs; wrote {stem}.{{json,md}}")
    return 0


def markdown(rec: dict) -> str:
    m = rec["machine"]
    L = [
        "# Segmentation cost, 512^3 benchmark volume: today against 7aadaac",
        "",
        f"`{rec['command']}` (started {rec['started_utc']}, {rec['total_s'] / 60:.1f} min in all).",
        "",
        f"Volume: {rec['volume']['recipe']} ({rec['volume']['n_rods_true']} rods, "
        f"{rec['volume']['contacts_true']} true contacts), as `benchmarks/bench_segment_scans.py` builds its "
        "512^3 timing case. Each segmentation ran in a fresh subprocess importing its tree's `rodwarp` "
        "(checked from `rodwarp.__file__`); timed: the `segment_volume` call alone. Trees alternated, before "
        f"then after, {rec['repeats']} pair(s). Scores: today's `match_rods` / `score_contacts`, whole volume.",
        "",
        f"Before: `{rec['before']['commit'][:7]}` ({rec['before']['tree']}); after: `{rec['after']['commit'][:7]}`"
        + (" with uncommitted changes under rodwarp/" if rec["after"]["rodwarp_dirty"] else "") + ".",
        "",
        f"Machine: {m['cpu_model']}, os.cpu_count() = {m['cpu_count']}, Python {m['python']}, numpy {m['numpy']}; "
        f"load average (1/5/15 min) at start {'/'.join(f'{x:.2f}' for x in rec['loadavg_start'])}, "
        f"at end {'/'.join(f'{x:.2f}' for x in rec['loadavg_end'])} (the machine is shared with other work).",
        "",
        "| pair | before (s) | after (s) | after / before | F1 before | F1 after | contact F1 before | contact F1 after |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for p in rec["pairs"]:
        b, a = p["before"], p["after"]
        L.append(f"| {p['pair']} | {b['time_s']:.1f} | {a['time_s']:.1f} | {p['ratio_after_over_before']:.3f} | "
                 f"{b['rod_f1']:.3f} | {a['rod_f1']:.3f} | {b['contact_f1']:.3f} | {a['contact_f1']:.3f} |")
    L += [f"| median | {rec['before_median_s']:.1f} | {rec['after_median_s']:.1f} | **{rec['ratio_median']:.3f}** "
          "| | | | |", "",
          f"Median of the per-pair ratios: **{rec['ratio_median']:.3f}** (ratio of the medians "
          f"{rec['ratio_of_medians']:.3f}); a ratio above 1 means today's code is slower.", ""]
    return "\n".join(L)


if __name__ == "__main__":
    sys.exit(main())
