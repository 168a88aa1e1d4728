"""Run every bad-input case of issue 15 through the real command line and tabulate what a user
sees: command, exit code, message. Writes ``benchmarks/results/bad_inputs.md``.

    python scripts/bad_inputs.py [--out DIR]

Each case runs ``rodwarp`` in a fresh process in a scratch folder (inputs it needs are made
there); the message is the error line (stderr) or, for a run that succeeds, its result line.
Cases that need a small tmpfs (full disk, read-only) are skipped where mounting is not allowed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SHORT = "--alpha 20 --n-rods 12 --entangle-duration 0.02 --duration 0.02 --save-every 0.01 --device cpu --quiet"


def rodwarp(args: str, cwd: Path, timeout=300):
    cmd = [sys.executable, "-m", "rodwarp.cli", *args.split()]
    t = time.perf_counter()
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - t
    err = [ln for ln in r.stderr.splitlines() if ln.strip() and "CUDA" not in ln]
    out = [ln for ln in r.stdout.splitlines() if ln.strip()]
    msg = err[-1] if err else (out[-1] if out else "")
    if not err and out and out[0].strip().startswith("Usage"):
        msg = out[0].strip() + " ... (help)"
    return r.returncode, msg.strip(), wall


def make_inputs(d: Path) -> None:
    from rodwarp.rodset import RodSet

    s = np.linspace(-0.5, 0.5, 10)
    flat = [np.stack([s, 0 * s, 0 * s], 1), np.stack([s, 0 * s + 0.3, 0 * s], 1)]
    RodSet.from_polylines(flat, radii=0.01, box=np.array([[-1.0, -1.0, 0.0], [1.0, 1.0, 1.0]])).save(d / "on_floor.npz")
    lines = [np.stack([s, 0 * s + 0.05 * k, 0 * s + 0.2], 1) for k in range(14)]
    lines[13] = np.stack([s, 0 * s + 0.05 * 12 + 0.001, 0 * s + 0.2], 1)  # rod 13 inside rod 12
    RodSet.from_polylines(lines, radii=0.005).save(d / "overlap.npz")
    RodSet.from_polylines(flat, radii=0.01).save(d / "alpha50.npz")  # l = 1 m, d = 0.02 m
    (d / "afile").write_text("not a folder")


def mount_tmpfs(path: Path, opts: str) -> bool:
    path.mkdir(exist_ok=True)
    return subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(path)], capture_output=True).returncode == 0


def killed_run(d: Path) -> None:
    args = [sys.executable, "-m", "rodwarp.cli", "simulate", *SHORT.split(), "--duration", "2", "--save-every", "0.05",
            "--checkpoint-every", "0.05", "--out", str(d / "killed")]  # the later --duration wins
    p = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=d)
    deadline = time.time() + 120
    while time.time() < deadline and p.poll() is None:
        ck = d / "killed" / "checkpoints"
        if ck.exists() and len(list(ck.glob("ckpt_*.npz"))) >= 2:
            os.kill(p.pid, signal.SIGKILL)
            break
        time.sleep(0.05)
    p.wait()


def cases(d: Path) -> list[tuple[str, str]]:
    """(what, arguments) in the order of the issue's table, then every other class."""
    c = [("zero-step run", f"simulate --dt 10 --out {d}/o"),
         ("non-finite", f"simulate --gravity inf --out {d}/o"),
         ("non-finite", f"simulate --save-every nan --out {d}/o"),
         ("non-finite", f"simulate --checkpoint-every inf --out {d}/o"),
         ("non-finite", f"simulate --length nan --out {d}/o"),
         ("oversized", f"simulate --n-rods 10000000 --out {d}/o"),
         ("oversized", f"simulate --alpha 1e9 --out {d}/o"),
         ("oversized", f"phantom random --shape 2000 2000 2000 --out {d}/big.tif"),
         ("oversized (steps)", f"simulate --alpha 1e9 --n-rods 10 --device cpu --quiet --out {d}/o9"),
         ("input on z = 0", f"simulate --initial {d}/on_floor.npz --duration 0.05 --save-every 0.01 --device cpu "
                            f"--quiet --out {d}/floor"),
         ("input overlap", f"simulate --initial {d}/overlap.npz --out {d}/o"),
         ("input alpha 50", f"simulate --initial {d}/alpha50.npz --duration 0.05 --save-every 0.01 --device cpu "
                            f"--quiet --out {d}/a50"),
         ("input alpha contradicted", f"simulate --initial {d}/alpha50.npz --alpha 100 --out {d}/o"),
         ("--out is a file", f"simulate {SHORT} --out {d}/afile"),
         ("--out under a file", f"analyze {d}/alpha50.npz --out {d}/afile/x"),
         ("segment --out is a file", f"segment {d}/alpha50.npz --voxel-size 1 --out {d}/afile"),
         ("sweep, all points invalid", f"sweep --alpha 0 --out {d}/sw"),
         ("sweep, non-finite", f"sweep --freq nan --out {d}/sw"),
         ("sweep, bad device", f"sweep --device bogus --out {d}/sw"),
         ("sweep, a point fails at run time", f"sweep --alpha 3 --freq 1 --entangle-duration 0.02 --duration 0.02 "
                                               f"--save-every 0.01 --workers 1 --device cpu --quiet --no-figures "
                                               f"--out {d}/swfail"),
         ("sweep, garbage scheduler", f"sweep --scheduler garbage --out {d}/sw"),
         ("sweep, closed port", f"sweep --scheduler tcp://127.0.0.1:1 --out {d}/sw"),
         ("sweep, unroutable address", f"sweep --scheduler tcp://10.255.255.1:8786 --out {d}/sw"),
         ("sweep, unknown host", f"sweep --scheduler tcp://no-such-host.invalid:8786 --out {d}/sw"),
         ("finished run in --out", f"simulate {SHORT} --out {d}/done"),
         ("  ... again, another seed", f"simulate {SHORT} --seed 1 --out {d}/done"),
         ("  ... --resume it", f"simulate {SHORT} --resume --out {d}/done"),
         ("  ... --overwrite", f"simulate {SHORT} --seed 1 --overwrite --out {d}/done"),
         ("killed run, rerun", f"simulate {SHORT} --duration 2 --save-every 0.05 --checkpoint-every 0.05 "
                               f"--out {d}/killed"),
         ("killed run, resume other params", f"simulate {SHORT} --duration 2 --save-every 0.05 --checkpoint-every "
                                             f"0.05 --gravity 0.6 --resume --out {d}/killed"),
         ("killed run, resume", f"simulate {SHORT} --duration 2 --save-every 0.05 --checkpoint-every 0.05 "
                                f"--resume --out {d}/killed"),
         ("analyze, then another --radius", f"analyze {d}/done --quiet --no-figures"),
         ("  ... --radius 0.2 (replaces it)", f"analyze {d}/done --quiet --no-figures --radius 0.2"),
         ("analyze into a simulation", f"analyze {d}/done --out {d}/done --quiet"),
         ("version", "--version"),
         ("bare rodwarp", ""),
         ("resume and overwrite", f"simulate {SHORT} --resume --overwrite --out {d}/o"),
         ("zero-step run", f"simulate {SHORT} --dt 0.03 --out {d}/o"),
         ("zero-length test", f"simulate {SHORT} --duration 0 --out {d}/o"),
         ("intervals disagree", f"simulate {SHORT} --save-every 0.5 --out {d}/o"),
         ("steps", f"simulate --freq 1e9 --out {d}/o"),
         ("box", f"simulate --box 0.3,0.3,0.3 --out {d}/o"),
         ("packing", f"simulate --alpha 20 --n-rods 5000 --out {d}/o"),
         ("integers", f"simulate --vertices 1 --out {d}/o"),
         ("integers", f"simulate --seed -1 --out {d}/o"),
         ("option the input decides", f"simulate --initial {d}/alpha50.npz --n-rods 5 --out {d}/o"),
         ("--entangle without --initial", f"simulate --entangle --out {d}/o"),
         ]
    for opt in ("alpha", "freq", "amplitude", "duration", "entangle-duration", "entangle-freq", "entangle-amplitude",
                "static-load", "mu", "young", "density", "dt"):
        c.append(("non-finite", f"simulate --{opt} nan --out {d}/o"))
    c.append(("non-finite", f"simulate --box 1,inf,2.5 --out {d}/o"))
    for opt in ("radius", "spacing", "diameter", "length", "contact-tolerance"):
        c.append(("non-finite", f"analyze {d}/alpha50.npz --{opt} inf --out {d}/an"))
    c.append(("oversized grid", f"analyze {d}/alpha50.npz --radius 0.01 --spacing 1e-5 --out {d}/an"))
    for opt in ("voxel-size", "blur", "cnr", "ring", "cupping", "streaks", "radius", "aspect", "touching"):
        c.append(("non-finite", f"phantom random --shape 64 64 64 --{opt} nan --out {d}/p.tif"))
    for opt in ("voxel-size", "diameter", "contact-tolerance"):
        extra = "" if opt == "voxel-size" else "--voxel-size 1 "
        c.append(("non-finite", f"segment {d}/alpha50.npz {extra}--{opt} nan --out {d}/seg"))
    for opt in ("alpha", "gravity", "static-load"):
        c.append(("non-finite", f"sweep --{opt} inf --out {d}/sw"))
    for opt in ("entangle-duration", "duration", "amplitude"):
        c.append(("non-finite", f"sweep --{opt} nan --out {d}/sw"))
    c.append(("sweep, test shorter than sampling", f"sweep --duration 0.05 --out {d}/sw"))
    c.append(("sweep, integers", f"sweep --seeds 0 --out {d}/sw"))
    return c


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bad_inputs.md"))
    args = ap.parse_args(argv)
    d = Path(tempfile.mkdtemp(prefix="rodwarp_bad_"))
    make_inputs(d)
    rows = []
    killed = False
    for what, a in cases(d):
        if "killed" in a and not killed:
            killed_run(d)
            killed = True
        rc, msg, wall = rodwarp(a, d)
        shown = ("rodwarp " + a).strip().replace(str(d), "$TMP")
        rows.append((what, shown, rc, msg.replace(str(d), "$TMP"), wall))
        print(f"{rc:>3}  {wall:5.1f}s  {shown}\n          {msg[:160]}", flush=True)
    # location problems on real small file systems
    for what, opts, a in (("--out on a nearly full disk (2 MB tmpfs)", "size=2m",
                           f"simulate {SHORT} --n-rods 200 --duration 1 --out {{m}}/run"),
                          ("--out on a full disk (16 kB tmpfs)", "size=16k", f"simulate {SHORT} --out {{m}}/run"),
                          ("--out on a read-only file system", "size=1m,ro", f"simulate {SHORT} --out {{m}}/run")):
        m = d / f"mnt{len(rows)}"
        if not mount_tmpfs(m, opts):
            rows.append((what, "(skipped: cannot mount a tmpfs here)", None, "", 0.0))
            continue
        try:
            rc, msg, wall = rodwarp(a.format(m=m), d)
            rows.append((what, ("rodwarp " + a.format(m=m)).replace(str(d), "$TMP"), rc, msg.replace(str(d), "$TMP"),
                         wall))
            print(f"{rc:>3}  {wall:5.1f}s  {rows[-1][1]}\n          {msg[:160]}", flush=True)
        finally:
            subprocess.run(["umount", str(m)], capture_output=True)
    shutil.rmtree(d, ignore_errors=True)
    lines = ["# Bad inputs and location problems: what a user sees", "",
             f"Generated by `python scripts/bad_inputs.py` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
             "every command ran in a fresh process ($TMP is a scratch folder). Exit codes: 0 done, 2 bad input or "
             "location, 4 a sweep with failed points.", "",
             "| case | command | exit | message | wall (s) |", "| --- | --- | --- | --- | --- |"]
    for what, cmd, rc, msg, wall in rows:
        lines.append(f"| {what} | `{cmd}` | {'' if rc is None else rc} | {msg.replace('|', '/')} | {wall:.1f} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
