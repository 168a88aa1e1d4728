"""``rodwarp analyze`` on the main job's output, end to end as a user runs it (a fresh process:
imports, fields, statistics, files, four figures), now and at the revision before issue 15.

The main job's folder comes from ``$RODWARP_MAIN_JOB``, else ``runs/alpha100_freq10_g0.5_seed0``
(or ``runs/alpha100_freq10``) under the repository, else the main job is run first (about 3
minutes on one core). The baseline revision (``$RODWARP_BASELINE_REV``, default the commit
issue 15 was filed against) is exported with ``git archive`` and run on the same folder.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import common

BASELINE_REV = os.environ.get("RODWARP_BASELINE_REV", "fa4b7db")
TARGET_S = 8.0


def _main_job() -> Path:
    env = os.environ.get("RODWARP_MAIN_JOB")
    if env:
        return Path(env)
    for name in ("alpha100_freq10_g0.5_seed0", "alpha100_freq10"):
        p = common.ROOT / "runs" / name
        if (p / "final.npz").exists():
            return p
    out = Path(tempfile.mkdtemp(prefix="rodwarp_main_")) / "run"
    common.log("no main-job output found: running `rodwarp simulate --alpha 100 --freq 10` first")
    r = subprocess.run([sys.executable, "-m", "rodwarp.cli", "simulate", "--alpha", "100", "--freq", "10", "--quiet",
                        "--device", "cpu", "--out", str(out)], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(r.stderr.strip().splitlines()[-1])
    return out


def _baseline_tree() -> Path | None:
    d = Path(tempfile.mkdtemp(prefix="rodwarp_base_"))
    tar = subprocess.run(["git", "archive", BASELINE_REV], cwd=common.ROOT, capture_output=True)
    if tar.returncode != 0:
        common.log(f"baseline {BASELINE_REV} not available: {tar.stderr.decode().strip()[:100]}")
        return None
    subprocess.run(["tar", "-x", "-C", str(d)], input=tar.stdout, check=True)
    (d / "rodwarp" / "kernels").symlink_to(d / "kernels")  # the package maps rodwarp.kernels to kernels/
    return d


def _time(cmd, env, repeats, outdir):
    walls = []
    for _ in range(repeats):
        shutil.rmtree(outdir, ignore_errors=True)
        t = time.perf_counter()
        r = subprocess.run(cmd + ["--out", str(outdir)], capture_output=True, text=True, env=env)
        walls.append(time.perf_counter() - t)
        if r.returncode != 0:
            raise RuntimeError(r.stderr.strip().splitlines()[-1] if r.stderr.strip() else "analyze failed")
    return walls


def run(quick: bool, device: str) -> dict:
    job = _main_job()
    repeats = common.n_repeats(quick)
    tmp = Path(tempfile.mkdtemp(prefix="rodwarp_an_"))
    env = dict(os.environ)
    cmd = [sys.executable, "-m", "rodwarp.cli", "analyze", str(job), "--quiet", "--device", device]
    now = _time(cmd, env, repeats, tmp / "now")
    nofig = _time(cmd + ["--no-figures"], env, repeats, tmp / "nofig")
    s = json.loads((tmp / "nofig" / "summary.json").read_text())
    rec = {"title": "rodwarp analyze on the main job's output (fresh process, four figures)",
           "main_job": str(job), "grid_zyx": s["grid_shape_zyx"], "now_s": common.spread(now),
           "no_figures_s": common.spread(nofig), "baseline_rev": BASELINE_REV, "baseline_s": None,
           "baseline_no_figures_s": None}
    base = _baseline_tree()
    if base is not None:
        benv = dict(env, PYTHONPATH=str(base))
        bcmd = [sys.executable, "-c", "import sys; from rodwarp.cli import main; sys.exit(main())", "analyze",
                str(job), "--quiet", "--device", device]
        rec["baseline_s"] = common.spread(_time(bcmd, benv, repeats, tmp / "base"))
        rec["baseline_no_figures_s"] = common.spread(_time(bcmd + ["--no-figures"], benv, repeats, tmp / "basenf"))
        shutil.rmtree(base, ignore_errors=True)
    shutil.rmtree(tmp, ignore_errors=True)
    return rec


def summary(rec: dict) -> list[dict]:
    rows = [{"benchmark": f"`rodwarp analyze` on the main job (grid {' x '.join(map(str, rec['grid_zyx']))} z,y,x), "
                          "with its four figures",
             "rodwarp": f"{common.fmt_spread(rec['now_s'], unit='s')} wall",
             "peer": (f"before issue 15 ({rec['baseline_rev']}): {common.fmt_spread(rec['baseline_s'], unit='s')}"
                      if rec.get("baseline_s") else f"target {TARGET_S:g} s"),
             "ratio": (rec["baseline_s"]["median"] / rec["now_s"]["median"]) if rec.get("baseline_s") else None},
            {"benchmark": "the same without figures (--no-figures)",
             "rodwarp": f"{common.fmt_spread(rec['no_figures_s'], unit='s')} wall",
             "peer": (f"before: {common.fmt_spread(rec['baseline_no_figures_s'], unit='s')}"
                      if rec.get("baseline_no_figures_s") else "—"),
             "ratio": (rec["baseline_no_figures_s"]["median"] / rec["no_figures_s"]["median"])
             if rec.get("baseline_no_figures_s") else None}]
    figs_now = rec["now_s"]["median"] - rec["no_figures_s"]["median"]
    line = f"figures now {figs_now:.2f} s"
    if rec.get("baseline_s"):
        line += f", before {rec['baseline_s']['median'] - rec['baseline_no_figures_s']['median']:.2f} s"
    rows.append({"benchmark": "four figures (difference of the two)", "rodwarp": line,
                 "peer": f"target: analyze under {TARGET_S:g} s", "ratio": None})
    return rows


def plot(rec: dict, outdir) -> list[dict]:
    return []
