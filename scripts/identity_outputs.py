"""Byte-for-byte outputs of five jobs, to show that a refactor changes no result.

Runs the main job (``rodwarp simulate --alpha 100 --freq 10``, defaults), an IMC job, a lab
job, an excitation job and the segmentation of the shipped real scan
(``examples/data/pcl_scaffold_128.tif``) and of a phantom, and writes the SHA-256 of every
output that carries a result: each CSV, every numeric array in every ``.npz`` byte for byte
(the zip's own time stamps are not results), and the JSON metadata (``summary.json``, an
``.npz``'s ``meta``) with wall times, versions, paths and dates left out and keys sorted. Run it on the code before a change and after it, then compare::

    python scripts/identity_outputs.py --out /tmp/before.json            # on the old checkout
    python scripts/identity_outputs.py --out /tmp/after.json --compare /tmp/before.json

``--code DIR`` runs another checkout's code (its ``rodwarp`` and ``kernels`` put first on
``PYTHONPATH``) with this environment, so the two can run side by side. ``--time-main K``
times the main job K times after the hashes (median wall seconds in the JSON); with
``--time-against DIR`` each timing alternates with DIR's main job, and the JSON holds the
median of the per-pair ratios (``ratio_this_over_other``).
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCAN = ROOT / "examples" / "data" / "pcl_scaffold_128.tif"

JOBS = {
    "main": ["simulate", "--alpha", "100", "--freq", "10"],
    "imc": ["simulate", "--alpha", "30", "--freq", "10", "--n-rods", "60", "--contact-law", "imc",
            "--entangle-duration", "0.3", "--duration", "0.3"],
    "lab": ["simulate", "--protocol", "lab", "--alpha", "20", "--length", "0.05", "--n-rods", "60",
            "--strains", "0,0.05", "--pour-duration", "0.3", "--press-duration", "0.1", "--lift-duration", "0.1",
            "--duration", "0.2", "--save-every", "0.05"],
    "excitation": ["simulate", "--protocol", "excitation", "--alpha", "20", "--n-rods", "60", "--duration", "0.2",
                   "--save-every", "0.05"],
    "segment_scan": ["segment", str(SCAN), "--voxel-size", "1", "--units", "voxel", "--shape", "curved"],
    "phantom": ["phantom", "random", "--shape", "128", "128", "128", "--n-rods", "30", "--aspect", "12", "--cnr", "5",
                "--seed", "3"],
}
# (job, input made by an earlier job): the segmentation of the phantom
DERIVED = {"segment_phantom": ("phantom", ["segment", "{in}/stack.tif", "--voxel-size", "0.078", "--units", "mm"])}

# summary.json keys that are not results (times, versions, paths, dates)
VOLATILE = {"wall_time_s", "wall_s", "elapsed_s", "versions", "version", "created", "date", "started", "finished",
            "command", "argv", "host", "device_name", "out", "path", "paths", "input", "timings", "time_s",
            "compile_s", "timing", "rodwarp", "warp", "python", "numpy", "hostname", "platform", "cpu", "pairs_s", "timings_s"}


def _scrub(obj):
    if isinstance(obj, dict):
        return {k: _scrub(v) for k, v in sorted(obj.items()) if k not in VOLATILE and not k.endswith("_wall_s")}
    if isinstance(obj, list):
        return [_scrub(v) for v in obj]
    return obj


def _digest_file(path: Path) -> dict[str, str]:
    if path.suffix == ".npz":
        out = {}
        with np.load(path, allow_pickle=False) as z:
            for k in sorted(z.files):
                a = np.ascontiguousarray(z[k])
                if a.dtype.kind in "US" and a.size == 1:
                    # metadata: JSON whose wall times and versions vary run to run; compared scrubbed,
                    # with sorted keys (every numeric array is compared byte for byte)
                    try:
                        text = json.dumps(_scrub(json.loads(str(a.reshape(()).item()))), sort_keys=True)
                        out[f"{path.name}:{k}"] = hashlib.sha256(text.encode()).hexdigest()[:16]
                        continue
                    except ValueError:
                        pass
                out[f"{path.name}:{k}"] = hashlib.sha256(a.dtype.str.encode() + str(a.shape).encode()
                                                         + a.tobytes()).hexdigest()[:16]
        return out
    if path.name == "summary.json":
        data = _scrub(json.loads(path.read_text()))
        return {path.name: hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]}
    return {path.name: hashlib.sha256(path.read_bytes()).hexdigest()[:16]}


def _digest_folder(folder: Path) -> dict[str, str]:
    out = {}
    for path in sorted(folder.rglob("*")):
        if path.is_file() and (path.suffix in (".csv", ".npz") or path.name == "summary.json"):
            if "checkpoint" in path.parts[-2] or "checkpoint" in path.name:
                continue
            for k, v in _digest_file(path).items():
                out[str(path.parent.relative_to(folder) / k)] = v
    return out


def _overlay(code: Path, where: Path) -> str:
    """A ``PYTHONPATH`` entry whose ``rodwarp`` is ``code``'s, with ``code/kernels`` as
    ``rodwarp.kernels`` (the installed layout): without it ``rodwarp.kernels`` would resolve
    through the environment's editable install to this checkout's kernels."""
    pkg = where / "rodwarp"
    pkg.mkdir(parents=True)
    for entry in (code / "rodwarp").iterdir():
        (pkg / entry.name).symlink_to(entry)
    (pkg / "kernels").symlink_to(code / "kernels")
    return str(where)


def _run(args, out: Path, env) -> float:
    target = out / "stack.tif" if args[0] == "phantom" else out  # a phantom is a file; its truth lies beside it
    cmd = [sys.executable, "-m", "rodwarp.cli", *args, "--out", str(target), "--quiet"]
    if args[0] == "simulate":
        cmd += ["--device", "cpu"]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed ({res.returncode}): {res.stderr.strip()[-2000:]}")
    return wall


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="JSON of the digests")
    ap.add_argument("--compare", type=Path, help="a JSON written before: report every digest that differs")
    ap.add_argument("--code", type=Path, default=ROOT, help="the checkout whose code runs (default: this one)")
    ap.add_argument("--only", default="", help="comma-separated jobs (default: all)")
    ap.add_argument("--time-main", type=int, default=0, help="time the main job this many more times")
    ap.add_argument("--time-against", type=Path, help="with --time-main: alternate each timing with this "
                                                      "checkout's main job (a same-run ratio)")
    a = ap.parse_args()
    only = set(filter(None, a.only.split(",")))
    result = {"code": str(a.code), "jobs": {}, "wall_s": {}}
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PYTHONPATH=_overlay(a.code.resolve(), Path(tmp) / "code"))
        for name, args in JOBS.items():
            if only and name not in only:
                continue
            out = Path(tmp) / name
            result["wall_s"][name] = _run(args, out, env)
            result["jobs"][name] = _digest_folder(out)
            print(f"{name}: {len(result['jobs'][name])} digests, {result['wall_s'][name]:.1f} s", flush=True)
        for name, (src, args) in DERIVED.items():
            if (only and name not in only) or src not in result["jobs"]:
                continue
            out = Path(tmp) / name
            result["wall_s"][name] = _run([x.replace("{in}", str(Path(tmp) / src)) for x in args], out, env)
            result["jobs"][name] = _digest_folder(out)
            print(f"{name}: {len(result['jobs'][name])} digests", flush=True)
        times, other = [], []
        env_other = (dict(os.environ, PYTHONPATH=_overlay(a.time_against.resolve(), Path(tmp) / "other"))
                     if a.time_against else None)
        for k in range(a.time_main):
            if env_other is not None:  # the other code first, then this, in turn
                other.append(_run(JOBS["main"], Path(tmp) / f"main_o{k}", env_other))
            times.append(_run(JOBS["main"], Path(tmp) / f"main_t{k}", env))
            print(f"main job {k + 1}: {times[-1]:.1f} s" + (f" (other {other[-1]:.1f} s)" if other else ""),
                  flush=True)
        if times:
            result["main_times_s"] = times
            result["main_median_s"] = statistics.median(times)
        if other:
            result["other_code"] = str(a.time_against)
            result["other_times_s"] = other
            result["other_median_s"] = statistics.median(other)
            result["ratio_this_over_other"] = statistics.median(t / o for t, o in zip(times, other))
    a.out.write_text(json.dumps(result, indent=1, sort_keys=True))
    if a.compare:
        before = json.loads(a.compare.read_text())["jobs"]
        diffs = []
        for job, digests in result["jobs"].items():
            old = before.get(job, {})
            for key in sorted(set(old) | set(digests)):
                if old.get(key) != digests.get(key):
                    diffs.append(f"{job}: {key}: {old.get(key)} -> {digests.get(key)}")
        print("\n".join(diffs) if diffs else "identical: every digest of every job matches")
        return 1 if diffs else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
