"""Run every bad-input case (issues 15, 29 and 47) through the real command line and tabulate what a
user sees: command, exit code, the lines on stderr, whether anything outside the case's output
changed, and whether the outcome is the one expected. Writes ``benchmarks/results/bad_inputs.md``.

    python scripts/bad_inputs.py [--out DIR]

Each case runs ``rodwarp`` in a fresh process in a scratch folder (inputs it needs are made
there, some by a setup step just before the case); the message is the error line (stderr) or,
for a run that succeeds, its result line. Every file in the scratch folder is fingerprinted
before and after each case: a change outside the case's own output (its ``--out``, an
analysis's default ``analysis/``, a phantom's TIFF and truth files) is reported. A case passes
when it gives the expected exit code (2 for bad input: exactly one ``error:`` line on stderr)
with no traceback and nothing outside its output touched.
Cases that need a small tmpfs (full disk, read-only) are skipped where mounting is not allowed.
Issue 47 adds binarised stacks (each two-level encoding of a phantom segmented and scored
against its truth: rod F1 >= 0.95) and misuses of the Python API (each in a fresh interpreter:
a TypeError or ValueError naming the argument, nothing else on stderr).

    python scripts/bad_inputs.py --only 47     # one issue's cases (written to --out)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
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


def rodwarp(args: str, cwd: Path, timeout=600, env: dict | None = None):
    """Run ``rodwarp ARGS`` in a fresh process (with ``env`` added to the environment): (exit
    code, message, stderr lines, traceback?, wall s)."""
    cmd = [sys.executable, "-m", "rodwarp.cli", *shlex.split(args)]
    t = time.perf_counter()
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                       env={**os.environ, **env} if env else None)
    wall = time.perf_counter() - t
    err = [ln for ln in r.stderr.splitlines() if ln.strip()]
    out = [ln for ln in r.stdout.splitlines() if ln.strip()]
    msg = err[-1] if err else (out[-1] if out else "")
    if not err and out and out[0].strip().startswith("Usage"):
        msg = out[0].strip() + " ... (help)"
    return r.returncode, msg.strip(), len(err), "Traceback" in r.stderr + r.stdout, wall


def _fingerprint(d: Path) -> dict:
    out = {}
    for root, dirs, files in os.walk(d):
        dirs[:] = [x for x in dirs if not x.startswith("mnt")]
        for f in files:
            p = Path(root) / f
            try:
                st = p.stat()
            except OSError:
                continue
            out[str(p)] = (st.st_size, st.st_mtime_ns)
    return out


def _own_outputs(args: str, d: Path) -> list[Path]:
    """What the case may change: its --out (and, for a phantom, the truth files beside the TIFF),
    an analysis's default analysis/ folder, a phase diagram's sweep folder."""
    tok = shlex.split(args)
    own = []
    if "--out" in tok:
        o = Path(tok[tok.index("--out") + 1])
        own.append(o)
        if tok and tok[0] == "phantom":
            stem = o.name.split(".")[0]
            own += [o.with_name(f"{stem}_truth.npz"), o.with_name(f"{stem}_truth.json")]
    elif tok and tok[0] == "analyze":
        src = Path(tok[1])
        own.append(src / "analysis" if src.is_dir() else src.parent / "analysis")
    elif tok and tok[0] == "segment":
        own.append(Path(tok[1]).parent / "segment")
    if tok and tok[0] == "phase-diagram":
        own.append(Path(tok[1]))
    return [o if o.is_absolute() else d / o for o in own]


def _touched_outside(before: dict, after: dict, own: list[Path]) -> list[str]:
    def mine(path: str) -> bool:
        return any(path == str(o) or path.startswith(str(o) + os.sep) for o in own)

    changed = [p for p in set(before) | set(after) if before.get(p) != after.get(p)]
    return sorted(p for p in changed if not mine(p))


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
    # issue 29: a finished run, its analysis, a phantom and a segmentation to aim commands at
    for args in (f"simulate {SHORT} --out {d}/base", f"analyze {d}/base --quiet --no-figures --out {d}/base_an",
                 f"phantom random --shape 48 48 48 --n-rods 4 --aspect 8 --radius 2.5 --cnr 12 --out {d}/p.tif",
                 f"segment {d}/p.tif --quiet --no-figures --out {d}/seg"):
        rc, msg, *_ = rodwarp(args, d)
        assert rc == 0, (args, msg)
    victim = d / "victim"
    (victim / "sub").mkdir(parents=True)
    (victim / "data.txt").write_text("a folder outside every run that must survive")
    (victim / "sub" / "more.txt").write_text("and its contents")


def _copy_run(d: Path, name: str) -> Path:
    dst = d / name
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(d / "base", dst)
    return dst


def _copy_phantom(d: Path, src: str, dst: str) -> None:
    for suffix in (".tif", "_truth.npz", "_truth.json"):
        shutil.copy(d / f"{src}{suffix}", d / f"{dst}{suffix}")


def _hostile(d: Path, folder: Path, entry: str) -> None:
    m = json.loads((folder / "rodwarp-run.json").read_text())
    m["outputs"].append(entry)
    (folder / "rodwarp-run.json").write_text(json.dumps(m))


_KILLER = (
    "import os, signal, sys\n"
    "from pathlib import Path\n"
    "real = os.replace\n"
    "def replace(src, dst, *a, **k):\n"
    "    if Path(dst).name == sys.argv[1]:\n"
    "        os.kill(os.getpid(), signal.SIGKILL)\n"
    "    return real(src, dst, *a, **k)\n"
    "os.replace = replace\n"
    "from rodwarp.cli import main\n"
    "sys.exit(main(sys.argv[2:]))\n")


def _kill_at(d: Path, target: str, args: str) -> None:
    """Run ``rodwarp ARGS`` and kill -9 it as it lands the output named ``target``."""
    r = subprocess.run([sys.executable, "-c", _KILLER, target, *shlex.split(args)], cwd=d, capture_output=True)
    assert r.returncode == -9, r.stderr[-500:]


TINY_SWEEP = ("sweep --alpha 20 --freq 1 --entangle-duration 0.02 --save-every 0.01 --workers 1 --device cpu "
              "--quiet --no-figures --set n_rods=12")


def cases_29(d: Path) -> list[tuple]:
    """Issue 29's classes: (class, what, arguments, setup or None, expected exit code)."""
    v = d / "victim"
    c = [
        ("1", "manifest lists an absolute folder; simulate --overwrite", f"simulate {SHORT} --seed 1 --overwrite "
         f"--out {d}/h_abs", lambda: _hostile(d, _copy_run(d, "h_abs"), str(v)), 2),
        ("1", "manifest lists ../../victim; a plain analyze --out", f"analyze {d}/base --quiet --no-figures --out "
         f"{d}/h_rel/an", lambda: (shutil.copytree(d / "base_an", d / "h_rel" / "an"),
                                   _hostile(d, d / "h_rel" / "an", "../../victim")), 2),
        ("1", "manifest lists a name no command writes; --overwrite", f"simulate {SHORT} --overwrite --out "
         f"{d}/h_name", lambda: _hostile(d, _copy_run(d, "h_name"), "notes.txt"), 2),
        ("1", "manifest of an unknown command; --overwrite", f"simulate {SHORT} --overwrite --out {d}/h_kind",
         lambda: (lambda f: (f / "rodwarp-run.json").write_text(
             (f / "rodwarp-run.json").read_text().replace('"kind": "simulate"', '"kind": "rm"')))(
             _copy_run(d, "h_kind")), 2),
        ("1", "phase-diagram of a sweep whose manifest lists a folder outside", f"phase-diagram {d}/h_sw",
         lambda: ((d / "h_sw").mkdir(), (d / "h_sw" / "results.csv").write_text("id\n"),
                  (d / "h_sw" / "rodwarp-run.json").write_text(json.dumps(
                      {"format": "rodwarp-run", "kind": "sweep", "outputs": ["results.csv", str(v)]}))), 2),
        ("2", "segment --out into a finished simulate run", f"segment {d}/p.tif --quiet --out {d}/base", None, 2),
        ("2", "segment --out into an analysis folder", f"segment {d}/p.tif --quiet --out {d}/base_an", None, 2),
        ("2", "phantom --out into a simulate run folder", f"phantom random --shape 48 48 48 --n-rods 4 --aspect 8 "
         f"--radius 2.5 --out {d}/base/stack.tif", None, 2),
        ("2", "phantom over a TIFF that is not a phantom", f"phantom random --shape 48 48 48 --n-rods 4 --aspect 8 "
         f"--radius 2.5 --out {d}/scan.tif", lambda: (d / "scan.tif").write_bytes(b"II*\x00 a real scan"), 2),
        ("2", "phantom over an earlier phantom (replaced)", f"phantom random --shape 48 48 48 --n-rods 5 --aspect 8 "
         f"--radius 2.5 --seed 3 --out {d}/p2.tif",
         lambda: _copy_phantom(d, "p", "p2"), 0),
        ("2", "sweep --out into a finished simulate run", f"{TINY_SWEEP} --duration 0.02 --out {d}/base", None, 2),
        ("2", "phase-diagram of a simulate run", f"phase-diagram {d}/base", None, 2),
        ("2", "a sweep (first protocol)", f"{TINY_SWEEP} --duration 0.02 --out {d}/sw2", None, 0),
        ("2", "  ... a second sweep there with another --duration", f"{TINY_SWEEP} --duration 0.04 --out {d}/sw2",
         None, 2),
        ("2", "  ... a second sweep there with another --set", f"{TINY_SWEEP} --duration 0.02 --set mu=0.3 "
         f"--out {d}/sw2", None, 2),
        ("2", "  ... more points of the same protocol (appended)", f"{TINY_SWEEP.replace('--alpha 20', '--alpha 20,25')}"
         f" --duration 0.02 --out {d}/sw2", None, 0),
        ("2", "segment after kill -9 while it replaced another stack's segmentation",
         f"segment {d}/p.tif --quiet --no-figures --out {d}/segk",
         lambda: (shutil.copytree(d / "seg", d / "segk"),
                  _kill_at(d, "summary.json", f"segment {d}/p2.tif --quiet --no-figures --out {d}/segk")), 0),
        ("2", "simulate after kill -9 while it wrote (not replaced silently)", f"simulate {SHORT} --out {d}/simk",
         lambda: _kill_at(d, "final.npz", f"simulate {SHORT} --out {d}/simk"), 2),
        ("2", "  ... --overwrite replaces it", f"simulate {SHORT} --overwrite --out {d}/simk", None, 0),
        ("5", "--device cuda without a GPU", f"simulate {SHORT.replace('--device cpu', '--device cuda')} "
         f"--out {d}/f_cuda", None, 2),
        ("5", "  ... the corrected command in the same folder", f"simulate {SHORT} --out {d}/f_cuda", None, 0),
        ("5", "a packing that cannot be placed (alpha 10)", f"simulate --alpha 10 --n-rods 60 --entangle-duration "
         f"0.02 --duration 0.02 --save-every 0.01 --device cpu --quiet --out {d}/f_pack", None, 2),
        ("5", "  ... the corrected command in the same folder", f"simulate {SHORT} --out {d}/f_pack", None, 0),
        ("5", "--resume in a folder that never held a run", f"simulate {SHORT} --resume --out {d}/f_res", None, 2),
        ("5", "  ... the command without --resume", f"simulate {SHORT} --out {d}/f_res", None, 0),
        ("7", "a CPU run prints no CUDA warning", f"simulate {SHORT} --out {d}/cpu_run", None, 0),
    ]
    return c


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


#: the other classes of issue 29 (units 3, silent acceptances 4, garbage 6, phase-diagram rows):
#: (class, what, arguments with $TMP for the scratch folder[, expected exit code, default 2]);
#: their inputs are made by :func:`make_inputs_29`
_TINY = "--duration 0.02 --save-every 0.01 --device cpu --quiet"
_SIM = f"--entangle-duration 0.02 {_TINY}"
EXTRA: list[tuple] = [
    ("3", "phantom of a rod set in metres at the default --voxel-size 1", "phantom $TMP/m.npz --shape 64 64 64 "
     "--out $TMP/u1.tif"),
    ("3", "phantom, scene radius below half a voxel", "phantom random --radius 0.1 --shape 32 32 32 --out $TMP/u2.tif"),
    ("3", "phantom, --ring 1e9 saturates the image", "phantom random --ring 1e9 --shape 32 32 32 --out $TMP/u3.tif"),
    ("3", "phantom, --streaks 5 saturates the image", "phantom random --streaks 5 --shape 32 32 32 --out $TMP/u4.tif"),
    ("3", "phantom, rods larger than the volume", "phantom $TMP/m.npz --voxel-size 0.0025 --shape 32 32 32 "
     "--out $TMP/u5.tif"),
    ("3", "simulate --initial, CSV without a radius column", f"simulate --initial $TMP/nor.csv {_TINY} --out $TMP/u6"),
    ("3", "simulate --initial, a CSV in um read as metres", f"simulate --initial $TMP/um.csv {_TINY} "
     "--amplitude 0.0005 --entangle-amplitude 0.001 --out $TMP/u7"),
    ("3", "simulate --units voxel", f"simulate --initial $TMP/r.csv --units voxel {_TINY} --out $TMP/u8"),
    ("3", "simulate --units without --initial", f"simulate --units mm {_TINY} --out $TMP/u9"),
    ("3", "simulate --diameter contradicts the file's radii", f"simulate --initial $TMP/mm.csv --units mm --diameter 3 "
     f"{_TINY} --amplitude 0.0005 --entangle-amplitude 0.001 --out $TMP/u10"),
    ("3", "analyze, CSV without a radius column", "analyze $TMP/nor.csv --quiet --out $TMP/u11"),
    ("3", "analyze --diameter contradicts the file's radii", "analyze $TMP/r.csv --diameter 0.5 --quiet --out $TMP/u12"),
    ("3", "analyze, um data declared as m with a fine --spacing", "analyze $TMP/um.csv --spacing 0.0001 --quiet "
     "--out $TMP/u13"),
    ("4", "a bundle of parallel rods analysed (S = 1 everywhere: valid)", "analyze $TMP/r.csv --quiet "
     "--out $TMP/bundle_an", 0),
    ("4", "duplicated rod analysed", "analyze $TMP/dup.npz --no-figures --quiet --out $TMP/g1"),
    ("4", "duplicated rod, reversed, simulated", f"simulate --initial $TMP/duprev.npz {_TINY} --out $TMP/g2"),
    ("4", "zero-length rod analysed", "analyze $TMP/zero.npz --no-figures --quiet --out $TMP/g3"),
    ("4", "one rod 1e9 m away widens the container", f"simulate --initial $TMP/far.npz {_TINY} --out $TMP/g4"),
    ("4", "duplicated rods as phantom input", "phantom $TMP/dup.npz --shape 16 16 16 --voxel-size 0.1 "
     "--out $TMP/g5.tif"),
    ("4", "empty --out (would write into the current folder)", "simulate --alpha 20 --n-rods 12 --out ''"),
    ("4", "empty --out= for analyze", "analyze $TMP/good.npz --out="),
    ("4", "friction coefficient 1e9", "simulate --alpha 20 --n-rods 12 --mu 1e9 --out $TMP/g6"),
    ("4", "--entangle with zero entangling time", "simulate --initial $TMP/good.npz --entangle --entangle-duration 0 "
     "--duration 0.02 --save-every 0.01 --out $TMP/g7"),
    ("4", "a checkpoint every step", "simulate --alpha 20 --n-rods 12 --checkpoint-every 1e-6 --out $TMP/g8"),
    ("4", "unknown contact law", "simulate --alpha 20 --n-rods 12 --contact-law hertz --out $TMP/g8a"),
    ("4", "IMC option without the IMC law", "simulate --alpha 20 --n-rods 12 --imc-nu 1e-3 --out $TMP/g8b"),
    ("4", "IMC delta given in metres (it is in diameters)", "simulate --alpha 20 --n-rods 12 --contact-law imc "
     "--imc-delta 5 --out $TMP/g8c"),
    ("4", "IMC slip tolerance zero", "simulate --alpha 20 --n-rods 12 --contact-law imc --imc-nu 0 --out $TMP/g8d"),
    ("6", "random bytes named .npz (no pickle advice)", "analyze $TMP/rand.npz --out $TMP/g9"),
    ("6", "a zip holding an object array named .npz", "simulate --initial $TMP/objects.npz --out $TMP/g10"),
    ("6", "random bytes named .csv", "simulate --initial $TMP/rand.csv --out $TMP/g11"),
    ("6", "a UTF-16 CSV", "analyze $TMP/utf16.csv --out $TMP/g12"),
    ("6", "a .zarr that is a plain file", "analyze $TMP/plain.zarr --out $TMP/g13"),
    ("6", "an RGB TIFF segmented as a volume", "segment $TMP/rgb.tif --voxel-size 1 --units voxel --out $TMP/g14"),
    ("6", "an RGB stack", "segment $TMP/rgbstack.tif --voxel-size 1 --units voxel --out $TMP/g15"),
    ("6", "a truncated TIFF (no library log lines)", "segment $TMP/cut.tif --voxel-size 1 --units voxel "
     "--out $TMP/g16"),
    ("6", "random bytes named .tif", "segment $TMP/rand.tif --voxel-size 1 --units voxel --out $TMP/g17"),
    ("6", "a 2 x 2 x 2 volume", "segment $TMP/small.tif --voxel-size 1 --units voxel --out $TMP/g18"),
    ("6", "phase-diagram, a binary results.csv", "phase-diagram $TMP/pd_bin"),
    ("6", "phase-diagram, results.csv with NUL bytes", "phase-diagram $TMP/pd_nul"),
    ("6", "phase-diagram, a CSV without the needed columns", "phase-diagram $TMP/pd_cols"),
    ("6", "phase-diagram, results.csv is a folder", "phase-diagram $TMP/pd_dir"),
    ("6", "phase-diagram, a row longer than the header", "phase-diagram $TMP/pd_long"),
    ("4", "phase-diagram, one point twice with opposite verdicts", "phase-diagram $TMP/pd_dup"),
    ("4", "phase-diagram, an ok row with NaN alpha", "phase-diagram $TMP/pd_nan"),
    ("4", "phase-diagram, an ok row with infinite a/g", "phase-diagram $TMP/pd_inf"),
    ("4", "phase-diagram, a verdict neither True nor False", "phase-diagram $TMP/pd_verdict"),
    ("4", "phase-diagram, a point id that is a path out of the sweep", "phase-diagram $TMP/pd_id"),
    ("4", "phase-diagram, a failed row is skipped and counted (a note)", "phase-diagram $TMP/pd_failed", 0),
]


#: a tiny sweep the sweep cases of issue 47 add their options to
_SWEEP47 = "sweep --alpha 20 --freq 1 --device cpu --quiet --out $TMP/sw47"
#: issue 47's findings, each through the real command line: (finding, what, arguments with $TMP,
#: expected exit code, what the message must say); inputs from :func:`make_inputs_47`
CASES_47: list[tuple] = [
    ("bounds", "lab --amplitude 1e3 (a/g 1e5)", "simulate --protocol lab --amplitude 1e3 --out $TMP/b1", 2,
     "--amplitude must be >= 0 m and <= 100 m"),
    ("bounds", "--freq 1e4", "simulate --freq 1e4 --out $TMP/b2", 2, "--freq must be >= 0 Hz and <= 1000 Hz"),
    ("bounds", "lab --amplitude 0.5 with 5 cm rods", "simulate --protocol lab --length 0.05 --gravity 9.81 --freq 1 "
     "--amplitude 0.5 --out $TMP/b3", 2, "more than 2 rod lengths"),
    ("bounds", "--imc-stiffness 1e30", "simulate --contact-law imc --imc-stiffness 1e30 --out $TMP/b4", 2,
     "--imc-stiffness must be"),
    ("bounds", "--imc-stiffness 1e12 (3e9 rod weights per delta)", "simulate --contact-law imc --imc-stiffness 1e12 "
     "--out $TMP/b5", 2, "rod weights per delta"),
    ("bounds", "--imc-delta 1e-12", "simulate --contact-law imc --imc-delta 1e-12 --out $TMP/b6", 2,
     "--imc-delta must be >= 0.01"),
    ("messages", "lab --entangled-from RUN", "simulate --protocol lab --entangled-from $TMP/base --out $TMP/m1", 2,
     "--entangled-from applies only with --protocol paper"),
    ("messages", "a lab run resumed with paper options", f"simulate {SHORT} --resume --out $TMP/labk", 2,
     "it holds a --protocol lab run"),
    ("messages", "analyze --radius 1e-9", "analyze $TMP/base --radius 1e-9 --quiet --out $TMP/m3", 2,
     "--radius 1e-09 m is below half the rods' diameter"),
    ("messages", "simulate --length 1e-9", "simulate --length 1e-9 --out $TMP/m4", 2, "--length must be >= 1e-05 m"),
    ("messages", "simulate --length 1e-4 (the stroke does not fit)", "simulate --length 1e-4 --out $TMP/m5", 2,
     "--amplitude 0.001 m (a stroke of 0.002 m) does not fit the box"),
    ("silent", "--fill-height with --n-rods", "simulate --protocol lab --fill-height 2 --n-rods 40 --out $TMP/s1", 2,
     "--fill-height and --n-rods both set"),
    ("folders", "simulate --initial R/final.npz --overwrite --out R",
     "simulate --initial $TMP/own/final.npz --duration 0.02 --save-every 0.01 --device cpu --quiet --overwrite "
     "--out $TMP/own", 2, "deletes first (final.npz)"),
    ("folders", "a run inside another run's folder", f"simulate {SHORT} --out $TMP/base/inner", 2,
     "in the folder of another run"),
    ("folders", "analyze R --out R/checkpoints", "analyze $TMP/base --quiet --out $TMP/base/checkpoints", 2,
     "checkpoints, an output of another run"),
    ("folders", "analyze R (its analysis/ inside R: allowed)", "analyze $TMP/base --quiet --no-figures", 0, ""),
    ("runaway", "sweep --workers 1000 on this machine", f"{_SWEEP47} --workers 1000", 2,
     "--workers 1000 is more than this machine's"),
    ("runaway", "sweep --workers 0", f"{_SWEEP47} --workers 0", 2,
     "--workers must be >= 1, got 0"),
    ("messages", "sweep --set out=...", f"{_SWEEP47} --set out=$TMP/x", 2,
     "--set out: a sweep writes each point into its own folder under the sweep's --out"),
    ("messages", "sweep --set resume=...", f"{_SWEEP47} --set resume=true", 2,
     "--set resume: a sweep resumes by itself"),
    ("messages", "sweep --set overwrite=...", f"{_SWEEP47} --set overwrite=true", 2,
     "--set overwrite: use the sweep's own --overwrite"),
    ("messages", "sweep --set quiet=...", f"{_SWEEP47} --set quiet=true", 2,
     "--set quiet: use the sweep's own --quiet"),
    ("messages", "sweep --set entangled_from=...", f"{_SWEEP47} --set entangled_from=$TMP/base", 2,
     "--set entangled_from: a sweep shares the entangled packing"),
    ("messages", "sweep --set initial=...", f"{_SWEEP47} --set initial=$TMP/alpha50.npz", 2,
     "--set initial: a sweep always starts each point from a random packing"),
    ("silent", "sweep --set n_rods=12 --set n_rods=13", f"{_SWEEP47} --set n_rods=12 --set n_rods=13", 2,
     "--set n_rods is given twice (n_rods=12 and n_rods=13)"),
    ("silent", "sweep --alpha 25,,50", "sweep --alpha 25,,50 --freq 1 --out $TMP/sw47", 2,
     "--alpha 25,,50: item 2 of 3 is empty"),
    ("silent", "sweep --alpha 25,50, (trailing comma)", "sweep --alpha 25,50, --freq 1 --out $TMP/sw47", 2,
     "--alpha 25,50,: item 3 of 3 is empty"),
    ("silent", "sweep --alpha 25,50,25 (a value twice)", "sweep --alpha 25,50,25 --freq 1 --out $TMP/sw47", 2,
     "--alpha 25,50,25: 25 is given twice"),
    ("silent", "simulate --strains 0,,0.1", "simulate --protocol lab --strains 0,,0.1 --quiet --out $TMP/lab47", 2,
     "--strains 0,,0.1: item 2 of 3 is empty"),
    ("silent", "sweep --save-every with --set save_every", f"{_SWEEP47} --save-every 0.02 --set save_every=0.01", 2,
     "--save-every 0.02 and --set save_every=0.01 both given"),
    ("binarised", "a constant stack", "segment $TMP/const.tif --voxel-size 1 --units voxel --quiet --out $TMP/sc1", 2,
     "volume is constant"),
    ('binarised', 'a label image of 4 phases', 'segment $TMP/labels.tif --voxel-size 1 --units voxel --quiet --out $TMP/sc2', 2,
     'label image'),
    ('binarised', 'a posterised stack of 8 values', 'segment $TMP/post8.tif --voxel-size 1 --units voxel --quiet --out $TMP/sc3', 2,
     'only 8 distinct values'),
    ('binarised', "a mask whose rods' level is a speck", 'segment $TMP/speck.tif --voxel-size 1 --units voxel --quiet --out $TMP/sc4', 2,
     'holds only 8 voxels'),
    ('binarised', 'an inverted mask read as bright rods', 'segment $TMP/inv.tif --voxel-size 1 --units voxel --quiet --out $TMP/sc5', 2,
     'pass --dark-rods'),
    ('binarised', '--dark-rods on a bright-rod mask', 'segment $TMP/fg.tif --voxel-size 1 --units voxel --quiet --dark-rods --out $TMP/sc6', 2,
     'pass --bright-rods'),
    ("messages", "1e300 coordinates, analyze", "analyze $TMP/big.csv --quiet --out $TMP/c1", 2,
     "points hold 1e+300 m (first at vertex 1), too large to be a length in 'm'"),
    ("messages", "1e300 coordinates, simulate", "simulate --initial $TMP/big.csv --quiet --out $TMP/c2", 2,
     "too large to be a length in 'm'"),
    ("messages", "RODWARP_KERNEL_CACHE is a file (simulate)", f"simulate {SHORT} --out $TMP/c3", 2,
     "RODWARP_KERNEL_CACHE=$TMP/cachefile: $TMP/cachefile is a file", {"RODWARP_KERNEL_CACHE": "$TMP/cachefile"}),
    ("messages", "RODWARP_KERNEL_CACHE under a file (analyze)", "analyze $TMP/ok.csv --keep-outside --quiet "
     "--out $TMP/c4", 2, "is a file, not a folder", {"RODWARP_KERNEL_CACHE": "$TMP/cachefile/sub"}),
    ("messages", "RODWARP_KERNEL_CACHE that cannot be created", "analyze $TMP/ok.csv --keep-outside --quiet "
     "--out $TMP/c5", 2, "RODWARP_KERNEL_CACHE=/proc/rodwarp-cache is not a writable folder",
     {"RODWARP_KERNEL_CACHE": "/proc/rodwarp-cache"}),
]


#: issue 47's misuses of the Python API: (what, the call, the error type it must raise, what its
#: message must say); each runs in a fresh interpreter (:func:`api_case`)
API_47: list[tuple] = [
    ("compute_fields('str')", "compute_fields('str')", "TypeError", "rods must be a RodSet"),
    ("field_statistics({'e': 1})", "field_statistics({'e': 1})", "TypeError", "fields must be a Fields object"),
    ("ModelBuilder([[0, 0, 0]])", "ModelBuilder([[0, 0, 0]])", "TypeError", "rods must be a RodSet"),
    ("ModelBuilder(rods, gravity=(0, 0, nan))", "ModelBuilder(ROD, gravity=(0, 0, float('nan')))", "ValueError",
     "gravity z must be a finite number"),
    ("ModelBuilder(rods, mu=-1)", "ModelBuilder(ROD, mu=-1)", "ValueError", "mu must be >= 0"),
    ("RodSet.from_polylines with 1e300 coordinates", "RodSet.from_polylines([[[0, 0, 0], [1e300, 0, 0]]], radii=0.01)",
     "ValueError", "too large to be a length"),
]
_API_PRELUDE = ("import numpy as np\nfrom rodwarp import ModelBuilder, RodSet\n"
                "from rodwarp.analysis import compute_fields, field_statistics\n"
                "ROD = RodSet.from_polylines([np.array([[0, 0, 0], [1, 0, 0.0]])], radii=0.01)\n")


def api_case(call: str, cwd: Path):
    """Run ``call`` in a fresh interpreter: (exception type names of its MRO or 'none', message,
    whether a warning or traceback reached stderr)."""
    code = (_API_PRELUDE + "try:\n    " + call + "\n    print('none|')\n"
            "except Exception as e:\n    print(','.join(c.__name__ for c in type(e).__mro__) + '|' + str(e))\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=300)
    kinds, _, msg = (r.stdout.strip().splitlines() or ["none|"])[-1].partition("|")
    noisy = "Traceback" in r.stderr or "Warning" in r.stderr
    return kinds.split(","), msg, noisy


def first_note_case(d: Path) -> tuple:
    """``--fill-height 40`` places 17,280 rods (about a minute here): the time from the command's
    start to its first line on stderr, which must be the placement's note (the row of the report;
    the run is stopped once the note is read)."""
    import select

    args = f"simulate --protocol lab --alpha 20 --fill-height 40 --save-every 0.025 --device cpu --out {d}/fh40"
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "rodwarp.cli", *shlex.split(args)], cwd=d, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    line, waited = "", 0.0
    try:
        while waited < 60:
            ready, _, _ = select.select([proc.stderr], [], [], 0.5)
            waited = time.perf_counter() - t
            if ready:
                line = proc.stderr.readline().strip()
                if line or proc.poll() is not None:
                    break
    finally:
        proc.kill()
        proc.wait()
    ok = line.startswith("note: placing 17280 rods")
    shown = ("rodwarp " + args).replace(str(d), "$TMP")
    print(f"{'pass' if ok else 'FAIL'}  first stderr line after {waited:.1f} s: {line[:120]}", flush=True)
    return ("47 silent", f"a long placement speaks: first stderr line {waited:.1f} s after the command started "
                         f"(imports, checks, then 2 s of placement)", shown, None, 1, "yes",
            "pass" if ok else "FAIL", line, waited)


def binarised_cases(d: Path) -> list[tuple]:
    """The 4-rod phantom (p.tif), thresholded at its half level and saved in every two-level
    encoding, segmented through the command line and scored against the phantom's truth (the
    grey scan's score beside them): rows of the report."""
    import tifffile

    from rodwarp.ct import match_rods
    from rodwarp.rodset import load
    from rodwarp.testing.binarised import ENCODINGS

    grey = tifffile.imread(d / "p.tif")
    truth = load(d / "p_truth.npz")
    mask = grey > 0.5 * (20000 + 50000)  # the phantom's background and rod levels: the half level
    out = []
    for name, encode in {"grey scan (reference)": None, **ENCODINGS}.items():
        tif = d / "p.tif" if encode is None else d / f"bin_{name.replace(' ', '_').replace('/', '_')}.tif"
        if encode is not None:
            tifffile.imwrite(tif, encode(mask))
        seg = d / f"seg_{tif.stem}"
        args = f"segment {tif} --voxel-size 1 --units voxel --quiet --no-figures --out {seg}"
        rc, msg, n_err, tb, wall = rodwarp(args, d)
        f1 = match_rods(load(seg / "rods.npz"), truth).f1 if rc == 0 else float("nan")
        said = encode is None or "binarised stack" in msg
        ok = rc == 0 and not tb and f1 >= 0.95 and said
        out.append(("47 binarised", f"{name}: rod F1 {f1:.2f} of the phantom's truth",
                    ("rodwarp " + args).replace(str(d), "$TMP"), rc, n_err, "yes", "pass" if ok else "FAIL",
                    msg.replace(str(d), "$TMP"), wall))
        print(f"{'pass' if ok else 'FAIL'}  {name}: F1 {f1:.2f}\n          {msg[:150]}", flush=True)
    return out


def make_inputs_47(d: Path) -> None:
    """The inputs of :data:`CASES_47`: a finished run to overwrite from inside, and a lab run
    left unfinished (as a kill leaves it) to resume with the paper's options."""
    shutil.copytree(d / "base", d / "own")
    rc, msg, *_ = rodwarp("simulate --protocol lab --alpha 20 --n-rods 30 --pour-duration 0.05 --lift-duration 0 "
                          "--duration 0.04 --save-every 0.02 --checkpoint-every 0.02 --device cpu --quiet "
                          f"--out {d}/labk", d)
    assert rc == 0, msg
    m = json.loads((d / "labk" / "rodwarp-run.json").read_text())
    m.update(complete=False, status="failed")
    (d / "labk" / "rodwarp-run.json").write_text(json.dumps(m))
    (d / "big.csv").write_text("rod,x,y,z,radius\n0,0,0,0,0.01\n0,1e300,0,0,0.01\n1,0,1e300,0,0.01\n"
                               "1,0,1e300,1e300,0.01\n")
    (d / "ok.csv").write_text("rod,x,y,z,radius\n0,0,0,0,0.001\n0,0.1,0,0,0.001\n1,0,0.01,0,0.001\n"
                              "1,0.1,0.01,0,0.001\n")
    (d / "cachefile").write_text("not a folder")
    import tifffile

    for name, arr in (("const", np.full((16, 32, 32), 255, np.uint8)),
                      ("labels", (np.indices((24, 24, 24)).sum(0) // 18).astype(np.uint8)),
                      ("post8", (np.arange(32**3).reshape(32, 32, 32) % 8).astype(np.uint8)),
                      ("speck", np.pad(np.ones((2, 2, 2), np.uint8), 15)),
                      ("inv", np.pad(np.zeros((4, 4, 40), np.uint8), 12, constant_values=1)),
                      ("fg", np.pad(np.ones((4, 4, 40), np.uint8), 12))):
        tifffile.imwrite(d / f"{name}.tif", arr)


def _write_csv(path: Path, rods, radius: bool = True) -> None:
    rows = ["rod,x,y,z" + (",radius" if radius else "")]
    for i in range(rods.n_rods):
        for x, y, z in rods.points[rods.offsets[i]:rods.offsets[i + 1]]:
            rows.append(f"{i},{float(x)!r},{float(y)!r},{float(z)!r}" + (f",{float(rods.radii[i])!r}" if radius else ""))
    path.write_text("\n".join(rows) + "\n")


def make_inputs_29(d: Path) -> None:
    """The inputs of :data:`EXTRA`: rod sets in several units, duplicated, empty and far-away
    rods, garbage files and broken TIFFs."""
    import zipfile

    import tifffile

    from rodwarp.rodset import RodSet

    rng = np.random.default_rng(0)
    s = np.linspace(-0.5, 0.5, 10)
    # six 0.1 m rods of radius 5 mm inside a 0.16 m cube, in metres
    six = [np.stack([0.08 + 0.1 * s, 0.02 + 0.02 * k + 0 * s, 0.03 + 0.02 * k + 0 * s], 1) for k in range(6)]
    RodSet.from_polylines(six, radii=0.005).save(d / "m.npz")
    # 16 rods 20 mm long, radius 0.5 mm, 4 mm apart in a 4 x 4 bundle: in m, mm and um, with and
    # without radii
    sixteen = RodSet.from_polylines([np.stack([0.02 * s, 0 * s + 0.004 * (k // 4), 0 * s + 0.001 + 0.004 * (k % 4)], 1)
                                     for k in range(16)], radii=0.0005)
    _write_csv(d / "r.csv", sixteen)
    _write_csv(d / "nor.csv", sixteen, radius=False)
    _write_csv(d / "mm.csv", sixteen.to_units("mm"))
    _write_csv(d / "um.csv", sixteen.to_units("um"))
    # 12 good rods (alpha 50) and their broken variants
    good = [np.stack([s, 0 * s + 0.1 * k, 0 * s + 0.1], 1) for k in range(12)]
    RodSet.from_polylines(good, radii=0.01).save(d / "good.npz")
    RodSet.from_polylines([*good, good[3].copy()], radii=0.01).save(d / "dup.npz")
    RodSet.from_polylines([*good, good[3][::-1].copy()], radii=0.01).save(d / "duprev.npz")
    RodSet.from_polylines([*good, np.zeros((4, 3)) + 0.3], radii=0.01).save(d / "zero.npz")
    RodSet.from_polylines([good[0] + [1e9, 0, 0], *good[1:]], radii=0.01).save(d / "far.npz")
    # garbage
    (d / "rand.npz").write_bytes(rng.bytes(4096))
    (d / "rand.csv").write_bytes(rng.bytes(4096))
    (d / "rand.tif").write_bytes(rng.bytes(5000))
    (d / "plain.zarr").write_bytes(rng.bytes(100))
    (d / "utf16.csv").write_bytes("rod,x,y,z,radius\n0,0,0,0,1\n".encode("utf-16"))
    with zipfile.ZipFile(d / "objects.npz", "w") as z:
        with z.open("meta.npy", "w") as fh:
            np.lib.format.write_array(fh, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    tifffile.imwrite(d / "rgb.tif", rng.integers(0, 255, (64, 64, 3), dtype=np.uint8), photometric="rgb")
    tifffile.imwrite(d / "rgbstack.tif", rng.integers(0, 255, (10, 64, 64, 3), dtype=np.uint8), photometric="rgb")
    tifffile.imwrite(d / "full.tif", rng.integers(0, 4000, (20, 32, 32), dtype=np.uint16))
    data = (d / "full.tif").read_bytes()
    (d / "cut.tif").write_bytes(data[: len(data) // 2])
    tifffile.imwrite(d / "small.tif", rng.integers(0, 4000, (2, 2, 2), dtype=np.uint16))
    # results.csv files a phase diagram must refuse (and one it draws with a note)
    head = "id,alpha,freq,gravity,static_load,seed,amplitude,a_over_g,largest_cluster_fraction,stable,status"
    rows = ["a50,50,10,0.5,0,0,0.001,7.9,0.3,False,ok", "a100,100,10,0.5,0,0,0.001,7.9,0.8,True,ok",
            "a200,200,10,0.5,0,0,0.001,7.9,0.9,True,ok"]

    def sweep_dir(name: str, text, *, binary: bool = False) -> None:
        (d / name).mkdir()
        f = d / name / "results.csv"
        f.write_bytes(text) if binary else f.write_text(text)

    def table(*extra: str, edit=lambda r: r) -> str:
        return "\n".join([head, *[edit(r) for r in rows], *extra]) + "\n"

    sweep_dir("pd_bin", b"\x89PNG\r\n\x1a\n\xff\xfe\x00\x01", binary=True)
    sweep_dir("pd_nul", (head + "\na50,50,10,0.5,0,0,0.001,7.9,0.3,False,ok\x00\n").encode(), binary=True)
    sweep_dir("pd_cols", "name,value\nfoo,1\n")
    (d / "pd_dir" / "results.csv").mkdir(parents=True)
    sweep_dir("pd_long", table("a300,300,10,0.5,0,0,0.001,7.9,0.9,True,ok,extra"))
    sweep_dir("pd_dup", table("a100,100,10,0.5,0,0,0.001,7.9,0.2,False,ok"))
    sweep_dir("pd_nan", table(edit=lambda r: r.replace("a100,100,", "a100,nan,")))
    sweep_dir("pd_inf", table(edit=lambda r: r.replace(",7.9,0.8,", ",inf,0.8,")))
    sweep_dir("pd_verdict", table(edit=lambda r: r.replace(",True,ok", ",maybe,ok") if r.startswith("a100") else r))
    sweep_dir("pd_id", table(edit=lambda r: r.replace("a100,", "../../etc,", 1)))
    sweep_dir("pd_failed", table("a25,25,10,0.5,0,0,0.001,,,,error: placed only 5 of 12 rods"))


#: what the message of an issue-29 case must say (a refusal for another reason fails the case)
SAYS = {
    "manifest lists an absolute folder; simulate --overwrite": "deletes nothing",
    "manifest lists ../../victim; a plain analyze --out": "deletes nothing",
    "manifest lists a name no command writes; --overwrite": "deletes nothing",
    "manifest of an unknown command; --overwrite": "unknown command",
    "phase-diagram of a sweep whose manifest lists a folder outside": "deletes nothing",
    "segment --out into a finished simulate run": "holds a finished simulate run",
    "segment --out into an analysis folder": "holds a finished analyze run",
    "phantom --out into a simulate run folder": "a phantom there would mix",
    "phantom over a TIFF that is not a phantom": "not a rodwarp phantom",
    "sweep --out into a finished simulate run": "holds a finished simulate run",
    "phase-diagram of a simulate run": "not a sweep",
    "  ... a second sweep there with another --duration": "duration 0.02 there, 0.04 here",
    "  ... a second sweep there with another --set": "another protocol",
    "simulate after kill -9 while it wrote (not replaced silently)": "holds an unfinished simulate run",
    "--device cuda without a GPU": "no CUDA device",
    "a packing that cannot be placed (alpha 10)": "placed only",
    "--resume in a folder that never held a run": "without --resume",
    "phantom of a rod set in metres at the default --voxel-size 1": "cannot resolve",
    "phantom, scene radius below half a voxel": "--radius",
    "phantom, --ring 1e9 saturates the image": "--ring",
    "phantom, --streaks 5 saturates the image": "--streaks",
    "phantom, rods larger than the volume": "do not fit the volume",
    "simulate --initial, CSV without a radius column": "no radius column",
    "simulate --initial, a CSV in um read as metres": "--units um",
    "simulate --units voxel": "--units voxel",
    "simulate --units without --initial": "only applies with --initial",
    "simulate --diameter contradicts the file's radii": "contradicts the radii",
    "analyze, CSV without a radius column": "no radius column",
    "analyze --diameter contradicts the file's radii": "contradicts the radii",
    "analyze, um data declared as m with a fine --spacing": "--units um",
    "duplicated rod analysed": "duplicates",
    "duplicated rod, reversed, simulated": "duplicates",
    "zero-length rod analysed": "zero length",
    "one rod 1e9 m away widens the container": "rod 0 lies",
    "duplicated rods as phantom input": "duplicates",
    "empty --out (would write into the current folder)": "--out is empty",
    "empty --out= for analyze": "--out is empty",
    "friction coefficient 1e9": "--mu",
    "--entangle with zero entangling time": "--entangle-duration 0",
    "a checkpoint every step": "--checkpoint-every",
    "unknown contact law": "--contact-law must be exact or imc",
    "IMC option without the IMC law": "only applies with --contact-law imc",
    "IMC delta given in metres (it is in diameters)": "in rod diameters",
    "IMC slip tolerance zero": "--imc-nu",
    "random bytes named .npz (no pickle advice)": "not a rod-set .npz",
    "a zip holding an object array named .npz": "object arrays",
    "random bytes named .csv": "not a text CSV",
    "a UTF-16 CSV": "UTF-16",
    "a .zarr that is a plain file": "not a zarr store",
    "an RGB TIFF segmented as a volume": "RGB image",
    "an RGB stack": "RGB image",
    "a truncated TIFF (no library log lines)": "truncated or corrupt",
    "random bytes named .tif": "not a TIFF",
    "a 2 x 2 x 2 volume": "too small",
    "phase-diagram, a binary results.csv": "not UTF-8",
    "phase-diagram, results.csv with NUL bytes": "NUL bytes",
    "phase-diagram, a CSV without the needed columns": "lacks the column",
    "phase-diagram, results.csv is a folder": "is a folder",
    "phase-diagram, a row longer than the header": "more cell",
    "phase-diagram, one point twice with opposite verdicts": "stable, data row 4: unstable",
    "phase-diagram, an ok row with NaN alpha": "alpha = 'nan'",
    "phase-diagram, an ok row with infinite a/g": "a_over_g = 'inf'",
    "phase-diagram, a verdict neither True nor False": "not True or False",
    "phase-diagram, a point id that is a path out of the sweep": "not a point's folder name",
}


def _cpu_model() -> str:
    """The processor the table was made on (the benchmarks' own provenance helper)."""
    sys.path.insert(0, str(ROOT))
    from benchmarks.common import cpu_model

    return cpu_model()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bad_inputs.md"))
    ap.add_argument("--only", help="run only the cases whose class starts with this (e.g. 47); a check of a part, "
                                   "written to --out")
    args = ap.parse_args(argv)
    d = Path(tempfile.mkdtemp(prefix="rodwarp_bad_"))
    make_inputs(d)
    make_inputs_29(d)
    make_inputs_47(d)
    rows = []
    killed = False
    ok_cases = {"input on z = 0", "input alpha 50", "finished run in --out", "  ... --overwrite", "killed run, resume",
                "analyze, then another --radius", "  ... --radius 0.2 (replaces it)", "version", "bare rodwarp"}
    plan = [("15", what, a, None, 0 if what in ok_cases else (4 if "fails at run time" in what else 2))
            for what, a in cases(d)] + cases_29(d) + [(e[0], e[1], e[2], None, e[3] if len(e) > 3 else 2)
                                                       for e in EXTRA]
    plan += [(f"47 {c[0]}", c[1], c[2], None, c[3]) for c in CASES_47]
    SAYS.update({c[1]: c[4].replace("$TMP", str(d)) for c in CASES_47})
    envs = {c[1]: {k: v.replace("$TMP", str(d)) for k, v in c[5].items()} for c in CASES_47 if len(c) > 5}
    if args.only:
        plan = [c for c in plan if c[0].startswith(args.only)]
    for cls, what, a, setup, expect in plan:
        a = a.replace("$TMP", str(d))
        if "killed" in a and not killed:
            killed_run(d)
            killed = True
        if setup is not None:
            setup()
        before = _fingerprint(d)
        rc, msg, n_err, tb, wall = rodwarp(a, d, env=envs.get(what))
        touched = _touched_outside(before, _fingerprint(d), _own_outputs(a, d))
        shown = ("rodwarp " + a).strip().replace(str(d), "$TMP")
        if what in envs:
            shown = " ".join(f"{k}={v}" for k, v in envs[what].items()).replace(str(d), "$TMP") + " " + shown
        one_line = n_err == 1 and msg.startswith("error:") if expect == 2 else True
        cuda = "CUDA" in msg or (expect == 0 and n_err and "cuda" not in a)
        advice = "pickle" in msg.lower() or "internal error" in msg  # never library advice, never a bug
        says = SAYS.get(what, "") in msg  # the refusal gives the case's own reason
        ok = (rc == expect and one_line and not tb and not touched and not advice and says
              and not (cls == "7" and cuda))
        rows.append((cls, what, shown, rc, n_err, "yes" if not touched else "NO: " + ", ".join(
            t.replace(str(d), "$TMP") for t in touched[:3]), "pass" if ok else "FAIL", msg.replace(str(d), "$TMP"),
            wall))
        print(f"{'pass' if ok else 'FAIL'} {rc:>3}  {wall:5.1f}s  {shown}\n          {msg[:160]}", flush=True)
    if not args.only or "47".startswith(args.only) or args.only.startswith("47"):
        rows += binarised_cases(d)
        rows.append(first_note_case(d))
        for what, call, kind, says in API_47:
            t = time.perf_counter()
            kinds, msg, noisy = api_case(call, d)
            ok = kind in kinds and says in msg and not noisy and "\n" not in msg
            rows.append(("47 API", what, f"python: {call.replace('ROD', 'rods')}", None, int(noisy), "yes",
                         "pass" if ok else "FAIL", f"{kinds[0]}: {msg}", time.perf_counter() - t))
            print(f"{'pass' if ok else 'FAIL'}  {what}\n          {kinds[0]}: {msg[:150]}", flush=True)
    # location problems on real small file systems
    for what, opts, a in (("--out on a nearly full disk (2 MB tmpfs)", "size=2m",
                           f"simulate {SHORT} --n-rods 200 --duration 1 --out {{m}}/run"),
                          ("--out on a full disk (16 kB tmpfs)", "size=16k", f"simulate {SHORT} --out {{m}}/run"),
                          ("--out on a read-only file system", "size=1m,ro", f"simulate {SHORT} --out {{m}}/run")):
        m = d / f"mnt{len(rows)}"
        if not mount_tmpfs(m, opts):
            rows.append(("15", what, "(skipped: cannot mount a tmpfs here)", None, 0, "", "skipped", "", 0.0))
            continue
        try:
            rc, msg, n_err, tb, wall = rodwarp(a.format(m=m), d)
            ok = rc == 2 and n_err == 1 and not tb
            rows.append(("15", what, ("rodwarp " + a.format(m=m)).replace(str(d), "$TMP"), rc, n_err, "yes",
                         "pass" if ok else "FAIL", msg.replace(str(d), "$TMP"), wall))
            print(f"{rc:>3}  {wall:5.1f}s  {rows[-1][2]}\n          {msg[:160]}", flush=True)
        finally:
            subprocess.run(["umount", str(m)], capture_output=True)
    shutil.rmtree(d, ignore_errors=True)
    n_pass = sum(r[6] == "pass" for r in rows)
    n_fail = sum(r[6] == "FAIL" for r in rows)
    from rodwarp._util import version_line

    lines = ["# Bad inputs and location problems: what a user sees", "",
             f"Generated by `python scripts/bad_inputs.py` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} "
             f"({version_line()}; {platform.node()}, {_cpu_model()}); every command "
             "ran in a fresh process ($TMP is a scratch folder). Exit codes: 0 done, 2 bad input or location, 4 a "
             "sweep with failed points. *class*: the issue and class the case comes from (15: issue 15; 1-9: the "
             "classes of issue 29; 47 and its finding: issue 47, where *binarised* rows give the rod F1 against "
             "the phantom's truth and *API* rows a Python call, its error type and message). *stderr*: lines on stderr. *outside*: every file of $TMP outside the case's "
             "own output is unchanged. *result*: the expected exit code (2 with exactly one `error:` line for bad "
             "input, naming the case's own reason for the cases of issue 29), no traceback, no library or "
             "pickle advice, nothing outside touched.", "",
             f"**{n_pass} pass, {n_fail} fail** of {len(rows)} cases.", "",
             "| class | case | command | exit | stderr | outside | result | message | wall (s) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for cls, what, cmd, rc, n_err, outside, verdict, msg, wall in rows:
        lines.append(f"| {cls} | {what} | `{cmd}` | {'' if rc is None else rc} | {n_err} | {outside} | {verdict} | "
                     f"{msg.replace('|', '/')} | {wall:.1f} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}: {n_pass} pass, {n_fail} fail")
    return 1 if n_fail else 0


if __name__ == "__main__":
    sys.exit(main())
