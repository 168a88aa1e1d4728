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


def _once(cmd, env, outdir) -> float:
    shutil.rmtree(outdir, ignore_errors=True)
    t = time.perf_counter()
    r = subprocess.run(cmd + ["--out", str(outdir)], capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(r.stderr.strip().splitlines()[-1] if r.stderr.strip() else "analyze failed")
    return wall


_WARM = """
import importlib.util, json, sys, time
from rodwarp.analysis import Fields
from rodwarp.analysis import _figures as new
from rodwarp.analysis import field_statistics, find_tangles
# the baseline's figure module imports rodwarp.stats, which issue 16 moved into rodwarp.analysis:
# give it that module under its old name, with the field lists it expects
import types
import rodwarp.analysis._stats as _st
shim = types.ModuleType("rodwarp.stats")
shim.__dict__.update(vars(_st), STAT_FIELDS=("phi", "S", "c", "e"), PROFILE_FIELDS=("phi", "S", "c", "e", "n"))
sys.modules.setdefault("rodwarp.stats", shim)
spec = importlib.util.spec_from_file_location("oldfp", sys.argv[2])
old = importlib.util.module_from_spec(spec); spec.loader.exec_module(old)
f = Fields.load(sys.argv[1])
st = field_statistics(f)
lab, _ = find_tangles(f.e, f.valid, st["e_lb"], connectivity=26, spacing=f.spacing, system_size=f.system_size)
def four(m):
    t = time.perf_counter()
    m.plot_histograms(f, st, sys.argv[3] + "/h.png"); m.plot_slices(f, sys.argv[3] + "/s.png")
    m.plot_zprofiles(st, sys.argv[3] + "/z.png"); m.plot_tangles(f, lab, st, sys.argv[3] + "/t.png")
    return time.perf_counter() - t
four(new); four(old)
out = {"new": [], "old": []}
for _ in range(int(sys.argv[4])):
    out["old"].append(four(old)); out["new"].append(four(new))
print(json.dumps(out))
"""


def _warm_figures(analysis: Path, base: Path, repeats: int) -> dict:
    """The four figures drawn again and again in one process (no import or font-loading
    cost), this revision's code against the baseline's, interleaved."""
    with tempfile.TemporaryDirectory() as d:
        r = subprocess.run([sys.executable, "-c", _WARM, str(analysis / "fields.zarr"),
                            str(base / "rodwarp" / "fieldplots.py"), d, str(repeats)], capture_output=True, text=True)
    if r.returncode != 0:
        common.log(f"warm figure timing failed: {r.stderr.strip().splitlines()[-1:]}")
        return {}
    t = json.loads(r.stdout.strip().splitlines()[-1])
    return {"figures_warm_now_s": common.spread(t["new"]), "figures_warm_before_s": common.spread(t["old"])}


def run(quick: bool, device: str) -> dict:
    job = _main_job()
    repeats = common.n_repeats(quick) + 2
    tmp = Path(tempfile.mkdtemp(prefix="rodwarp_an_"))
    env = dict(os.environ)
    cmd = [sys.executable, "-m", "rodwarp.cli", "analyze", str(job), "--quiet", "--device", device]
    variants = {"now_s": (cmd, env), "no_figures_s": (cmd + ["--no-figures"], env)}
    base = _baseline_tree()
    if base is not None:
        benv = dict(env, PYTHONPATH=str(base))
        bcmd = [sys.executable, "-c", "import sys; from rodwarp.cli import main; sys.exit(main())", "analyze",
                str(job), "--quiet", "--device", device]
        variants.update({"baseline_s": (bcmd, benv), "baseline_no_figures_s": (bcmd + ["--no-figures"], benv)})
    walls: dict = {k: [] for k in variants}
    # interleaved (now, before, now, before, ...): a shared machine's load drifts during the run
    for _ in range(repeats):
        for k, (c, e) in variants.items():
            walls[k].append(_once(c, e, tmp / k))
    s = json.loads((tmp / "no_figures_s" / "summary.json").read_text())
    rec = {"title": "rodwarp analyze on the main job's output (fresh process, four figures)",
           "main_job": str(job), "grid_zyx": s["grid_shape_zyx"], "baseline_rev": BASELINE_REV, "repeats": repeats,
           "baseline_s": None, "baseline_no_figures_s": None, "load_average": os.getloadavg()}
    rec.update({k: common.spread(v) for k, v in walls.items()})
    if base is not None:
        rec.update(_warm_figures(tmp / "now_s", base, repeats))
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
    if rec.get("figures_warm_now_s"):
        rows.append({"benchmark": "four figures drawn in a warm process (no imports, fonts loaded)",
                     "rodwarp": common.fmt_spread(rec["figures_warm_now_s"], unit="s"),
                     "peer": f"before: {common.fmt_spread(rec['figures_warm_before_s'], unit='s')} "
                             "(constrained layout)",
                     "ratio": rec["figures_warm_before_s"]["median"] / rec["figures_warm_now_s"]["median"]})
    la = rec.get("load_average")
    if la:
        rows.append({"benchmark": "machine load while measuring (1, 5, 15 min load average)",
                     "rodwarp": ", ".join(f"{x:.1f}" for x in la), "peer": "on 2 cores shared with other runs",
                     "ratio": None})
    return rows


def plot(rec: dict, outdir) -> list[dict]:
    return []
