"""What sets alpha*, with the controls a referee asks for (issue 51; docs/transition.md, "What sets
alpha*: the controls").

Every test here lasts the same number of drive cycles (``--cycles 50``) and is sampled eight times
a cycle (``--samples-per-cycle 8``), so that each cycle's landed packing (its lowest centroid) is
caught; the verdict is read on the landed measures (docs/verdict.md, "The landed phase") beside
the end-of-test values. The drive is stated by its amplitude over the rod length, A / l, and its
peak acceleration over gravity, a/g; the throw height (A omega)^2 / (g l) = (a/g)(A/l) is the
height, in rod lengths, that the floor's top speed throws a free body. The paper's protocol runs at
two scales with the same dimensionless entangling (A_e / l = 0.05, a_e / g = 19.7, 50 cycles):

* ``paper``: l = 1 m, g = 10 m/s^2 (the paper's "Numerical simulations" at its g ~ 10): elastic
  rods at alpha >= 50 by the sag rule;
* ``lab``: l = 50 mm, g = 9.81 m/s^2 (the paper's laboratory rods, Methods "Mechanical Testing"):
  the same steel rods are 20 times stiffer against their weight, rigid up to alpha 125 by the sag
  rule, so a cycle costs a fraction of the paper scale's.

The study is a list of blocks (:data:`BLOCKS`), run in that order: each block a scale, a contact
law, alphas, seeds and drives; the points of one (block, alpha, seed) share one entangled packing
(the first drive's run is the donor of the others, ``run_point(..., entangled_from=...)``).

    python scripts/alpha_star_controls.py plan                       # the points and their order
    python scripts/alpha_star_controls.py run --runs RUNS [--workers 2] [--only BLOCK,...]
    python scripts/alpha_star_controls.py report --runs RUNS         # tables and charts

``run`` is resumable: run it again and finished points are skipped, an interrupted point goes on
from its checkpoint. Each finished point is a JSON row in ``RUNS/rows/`` (written atomically);
``RUNS/INCOMPLETE`` marks a study still running or interrupted. ``report`` writes
``benchmarks/results/transition/controls/`` (``results.csv``, ``brackets.csv``, ``controls.md``,
``drive_map.png``, ``brackets.png``, ``landed_cycles.png``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "transition" / "controls"

#: test length in drive cycles and samples per cycle (the landed phase needs at least 4)
CYCLES = 50
SAMPLES_PER_CYCLE = 8
#: the scales: rod length (m) and gravity (m/s^2)
SCALES = {"paper": (1.0, 10.0), "lab": (0.05, 9.81)}
#: the paper protocol's entangling at l = 1 m, g = 10 (docs/protocol.md): 10 Hz, 0.05 m, 5 s; other
#: scales keep A_e / l, a_e / g and the number of cycles
ENTANGLE = (10.0, 0.05, 5.0)
#: the drives, by name: (A / l, a / g)
DRIVES = {
    "l/1000 a/g 1": (0.001, 1.0), "l/1000 a/g 2.5": (0.001, 2.5), "l/1000 a/g 7.9": (0.001, 7.9),
    "l/20 a/g 1": (0.05, 1.0), "l/20 a/g 2.5": (0.05, 2.5),
    "l/2 a/g 1": (0.5, 1.0), "l/2 a/g 2.5": (0.5, 2.5),
}
ALL_DRIVES = tuple(DRIVES)
LARGE = ("l/20 a/g 2.5",)
#: the contact laws: name -> simulate overrides
LAWS = {"exact": {}, "exact locked": {"rolling": False},
        "IMC nu 1e-3": {"contact_law": "imc", "imc_nu": 1e-3},
        "IMC nu 1e-4": {"contact_law": "imc", "imc_nu": 1e-4},
        "IMC nu 1e-2": {"contact_law": "imc", "imc_nu": 1e-2},
        # the exact law with a Newton restitution: IMC at DisMech's explicit 1e-5 s bounces with
        # e 0.8-1.0 at l = 1 m and 0.5-0.9 for lab rods (docs/physics.md, "Restitution")
        "exact e 0.9": {"restitution": 0.9}}


@dataclass(frozen=True)
class Block:
    """One part of the study: every (alpha, seed) of it runs every drive of it."""

    name: str
    factor: str
    scale: str
    law: str
    alphas: tuple
    seeds: tuple
    drives: tuple
    extra: tuple = ()  # further simulate overrides, as (key, value) pairs
    why: str = ""


#: the study, in the order it runs (the brackets at each drive first; seeds 3-4 at the bracketing
#: alphas once the first three say where the bracket lies)
BLOCKS = (
    Block("lab-drives", "drive", "lab", "exact", (25, 50, 100), (0, 1, 2), ALL_DRIVES,
          why="the (A, a/g) map at the laboratory's scale, where rods up to alpha 125 are rigid"),
    Block("paper-baseline", "baseline", "paper", "exact", (25, 50), (0, 1, 2),
          ("l/1000 a/g 1", "l/1000 a/g 2.5", "l/20 a/g 2.5"),
          why="the paper scale's baseline and the large drive: ties the lab scale to the earlier rows"),
    Block("lab-imc", "contact law", "lab", "IMC nu 1e-3", (50, 100), (0, 1, 2), LARGE,
          why="IMC under the drive that moves alpha*"),
    Block("paper-bounce", "restitution", "paper", "exact e 0.9", (25, 50, 100), (0, 1, 2), ("l/1000 a/g 1",),
          why="contacts that bounce as IMC's do at DisMech's step, at the paper's drive"),
    Block("lab-bounce", "restitution", "lab", "exact e 0.9", (25, 50, 100), (0, 1, 2),
          ("l/1000 a/g 1", "l/20 a/g 2.5"), why="contacts that bounce, at the lab's scale, small and large drive"),
    Block("paper-imc-large", "contact law", "paper", "IMC nu 1e-3", (100,), (0, 1, 2), LARGE,
          why="IMC under the large drive at the paper's scale (elastic rods), where IMC runs; at the lab scale "
              "IMC with rigid rods blew up in the entangling (lab-imc)"),
    Block("paper-large", "drive", "paper", "exact", (100,), (0, 1, 2), ("l/1000 a/g 1", "l/20 a/g 2.5"),
          why="alpha 100 under the large drive at the paper's scale (elastic rods), against the lab scale's"),
    Block("paper-laws", "contact law", "paper", "exact locked", (15, 25, 50), (0, 1, 2), ("l/1000 a/g 1",),
          why="the exact law with the spin locked, at the baseline drive"),
    Block("paper-N540", "number of rods", "paper", "exact", (15, 25), (0, 1, 2), ("l/1000 a/g 1",),
          extra=(("n_rods", 540),), why="N = 540 at every alpha, the box widened to keep the packing's height"),
    Block("paper-imc", "contact law", "paper", "IMC nu 1e-3", (15, 25, 50), (0, 1, 2), ("l/1000 a/g 1",),
          why="IMC at the baseline drive, 50 cycles"),
    Block("lab-200", "drive", "lab", "exact", (200,), (0, 1), ("l/20 a/g 2.5", "l/2 a/g 2.5"),
          why="alpha 200 (elastic at this scale too) where alpha 100 fails"),
    Block("lab-200-s2", "drive", "lab", "exact", (200,), (2,), ("l/20 a/g 2.5", "l/2 a/g 2.5"),
          why="alpha 200, the third seed"),
    Block("lab-drives-5", "drive", "lab", "exact", (25, 50), (3, 4), ALL_DRIVES,
          why="five seeds at the alphas of the small drives' bracket"),
    Block("lab-drives-100-5", "drive", "lab", "exact", (100,), (3, 4), ALL_DRIVES,
          why="five seeds at alpha 100"),
    Block("lab-200-5", "drive", "lab", "exact", (200,), (3, 4), ("l/20 a/g 2.5", "l/2 a/g 2.5"),
          why="five seeds at alpha 200 under the large drives"),
    Block("paper-baseline-5", "baseline", "paper", "exact", (25, 50), (3, 4),
          ("l/1000 a/g 1", "l/1000 a/g 2.5", "l/20 a/g 2.5"), why="five seeds at the baseline's bracket"),
    Block("lab-imc-200", "contact law", "lab", "IMC nu 1e-3", (200,), (0, 1, 2), LARGE,
          why="IMC at alpha 200 under the large drive"),
    Block("paper-imc-1e-4", "contact law", "paper", "IMC nu 1e-4", (15, 25, 50), (0, 1, 2), ("l/1000 a/g 1",)),
    Block("paper-imc-1e-2", "contact law", "paper", "IMC nu 1e-2", (15, 25, 50), (0, 1, 2), ("l/1000 a/g 1",)),
)
BLOCK_NAMES = {b.name: b for b in BLOCKS}
#: blocks whose rows join another block's brackets (more seeds or alphas of the same level)
LEVEL_OF = {"lab-200-s2": "lab-drives", "lab-drives-5": "lab-drives", "lab-drives-100-5": "lab-drives", "lab-200": "lab-drives",
            "lab-200-5": "lab-drives", "paper-baseline-5": "paper-baseline", "paper-large": "paper-baseline",
            "lab-imc-200": "lab-imc"}


def drive_freq(a_over_l: float, ag: float, length: float, gravity: float) -> float:
    """Frequency (Hz) of a drive of amplitude ``a_over_l`` rod lengths and peak a/g ``ag``."""
    return math.sqrt(ag * gravity / (a_over_l * length)) / (2 * math.pi)


def throw_height(a_over_l: float, ag: float) -> float:
    """(A omega)^2 / (g l) = (a/g)(A/l): how high, in rod lengths, the floor's top speed throws
    a free body (twice the free-flight apex, dimensionless)."""
    return ag * a_over_l


def entangling(scale: str) -> dict:
    """The entangling drive at ``scale``: the paper's 10 Hz, 5 cm, 5 s at l = 1 m, g = 10, the
    same A_e / l, a_e / g and cycles elsewhere."""
    length, g = SCALES[scale]
    f0, a0, t0 = ENTANGLE
    amp = a0 * length
    ag = (2 * math.pi * f0) ** 2 * a0 / 10.0
    f = math.sqrt(ag * g / amp) / (2 * math.pi)
    return {"entangle_amplitude": amp, "entangle_freq": f, "entangle_duration": t0 * f0 / f}


def _box(n_rods: int, alpha: float) -> tuple:
    """The 1 x 1 x 2.5 box widened for ``n_rods`` rods so that they start as high as round(5.4 alpha)."""
    w = math.sqrt(n_rods / round(5.4 * alpha))
    return (round(w, 4), round(w, 4), 2.5)


def point(block: Block, alpha: float, seed: int, drive: str) -> dict:
    """One run: a flat dict of simulate parameters with ``id``, ``_block``, ``_drive``, ``_scale``,
    ``_law`` (the sweep's :func:`run_point` takes it)."""
    length, g = SCALES[block.scale]
    a_over_l, ag = DRIVES[drive]
    p = {"alpha": float(alpha), "seed": int(seed), "length": length, "gravity": g,
         "freq": drive_freq(a_over_l, ag, length, g), "amplitude": a_over_l * length,
         "cycles": CYCLES, "samples_per_cycle": SAMPLES_PER_CYCLE, "fields_every": 0.0,
         **entangling(block.scale), **LAWS[block.law], **dict(block.extra), "device": "cpu"}
    if "n_rods" in p:
        p["box"] = _box(p["n_rods"], alpha)
    tag = drive.replace("/", "").replace(" ", "").replace("a", "")
    p["id"] = f"{block.name}_alpha{alpha:g}_seed{seed}_{tag}"
    p.update({"_block": block.name, "_drive": drive, "_scale": block.scale, "_law": block.law, "_analyze": {}})
    return p


def groups(blocks) -> list[list[dict]]:
    """The points by (block, alpha, seed): one entangled packing each, its drives in order (the
    cheapest test first: it runs the entangling)."""
    out = []
    for b in blocks:
        for alpha in b.alphas:
            for seed in b.seeds:
                pts = [point(b, alpha, seed, d) for d in b.drives]
                out.append(sorted(pts, key=lambda q: q["cycles"] / q["freq"]))
    return out


#: Gauss-Seidel sweeps of a point's second try after the engine stopped its first
RETRY_ITERATIONS = 20


def salvage(row: dict, folder: Path) -> dict:
    """A point whose simulation finished but whose field analysis refused the final packing (a
    pile spread into a layer no ball fits, a rod thrown a hundred rod lengths away): its
    results from summary.json, ``status`` ok, the analysis's refusal kept in ``analysis``
    (cv_e stays empty). Any other row is returned as it is."""
    sys.path.insert(0, str(ROOT))
    from rodwarp.experiments._sweep import summary_columns

    summary = folder / "summary.json"
    if row.get("status") == "ok" or str(row.get("status")).startswith("SimulationBlowUp") or not summary.exists():
        return row
    return {**row, **summary_columns(json.loads(summary.read_text())), "analysis": row["status"], "status": "ok"}


def _row_path(runs: Path, pid: str) -> Path:
    return runs / "rows" / f"{pid}.json"


def run_group(pts: list[dict], runs: str) -> list[dict]:
    """Run the points of one entangled packing in order (the first is the others' donor);
    each finished row is written to ``runs/rows/<id>.json``. Returns the rows."""
    sys.path.insert(0, str(ROOT))
    from rodwarp.experiments._sweep import run_point
    from rodwarp.rodset.files import write_json

    runs = Path(runs)
    rows, donor, donor_row = [], None, None
    for p in pts:
        path = _row_path(runs, p["id"])
        if path.exists():
            row = json.loads(path.read_text())
        else:
            sim = {k: v for k, v in p.items() if not k.startswith("_") or k == "_analyze"}
            row = run_point(sim, str(runs / "points" / p["id"]), entangled_from=donor, donor_row=donor_row)
            if str(row.get("status")).startswith("SimulationBlowUp") and "iterations" not in sim:
                # the engine stopped the run (rods overlapping by a quarter diameter after a hard
                # landing): once more with 20 Gauss-Seidel sweeps, as the excitation experiment
                # runs (docs/experiments.md), its own entangling included; the row says so
                first = row["status"]
                sim = {**sim, "iterations": RETRY_ITERATIONS}
                row = run_point(sim, str(runs / "points" / f"{p['id']}_it{RETRY_ITERATIONS}"))
                row["retried"] = f"{RETRY_ITERATIONS} sweeps after, at 10: {first}"
                row["_folder"] = f"{p['id']}_it{RETRY_ITERATIONS}"
            row = salvage(row, runs / "points" / row.get("_folder", p["id"]))
            row.update({k: p[k] for k in ("_block", "_drive", "_scale", "_law")})
            row["throw_height"] = throw_height(*DRIVES[p["_drive"]])
            write_json(path, row)
        rows.append(row)
        if donor is None and row.get("status") == "ok" and "retried" not in row:
            donor, donor_row = str(runs / "points" / p["id"]), row
    return rows


def _select(only: str | None) -> tuple:
    if not only:
        return BLOCKS
    names = [s.strip() for s in only.split(",") if s.strip()]
    bad = [n for n in names if n not in BLOCK_NAMES]
    if bad:
        raise SystemExit(f"error: unknown block(s) {', '.join(bad)}; the blocks are {', '.join(BLOCK_NAMES)}")
    return tuple(BLOCK_NAMES[n] for n in names)


def cmd_plan(args) -> int:
    for b in _select(args.only):
        gs = groups([b])
        print(f"{b.name}: {b.factor}, {b.scale} scale, {b.law}, alphas {list(b.alphas)}, seeds {list(b.seeds)}, "
              f"{len(gs)} packings x {len(b.drives)} drives")
        for p in gs[0]:
            print(f"    {p['_drive']:>15}: f = {p['freq']:.4g} Hz, A = {p['amplitude'] * 1e3:.4g} mm, "
                  f"test {p['cycles'] / p['freq']:.3g} s, throw height {throw_height(*DRIVES[p['_drive']]):.3g} l")
    return 0


def cmd_run(args) -> int:
    from concurrent.futures import ProcessPoolExecutor, as_completed

    sys.path.insert(0, str(ROOT))
    from rodwarp._util import progress_bar
    from rodwarp.rodset.files import write_json, write_text

    runs = Path(args.runs)
    (runs / "rows").mkdir(parents=True, exist_ok=True)
    for path in (runs / "rows").glob("*.json"):  # rows written before salvage and the retry existed
        row = json.loads(path.read_text())
        if str(row.get("status")).startswith("SimulationBlowUp") and "retried" not in row:
            path.unlink()  # run again: from its last checkpoint, then the retry
        elif row.get("status") != "ok":
            fixed = salvage(row, runs / "points" / row.get("_folder", row["id"]))
            if fixed is not row:
                write_json(path, fixed)
    todo = [g for g in groups(_select(args.only)) if not all(_row_path(runs, p["id"]).exists() for p in g)]
    n = sum(len(g) for g in todo)
    write_text(runs / "INCOMPLETE", f"started {time.strftime('%Y-%m-%d %H:%M:%S')}: {n} points to run; "
                                    "run the same command again to go on\n")
    failed = 0
    with progress_bar(not args.quiet, "points", note=True) as update, \
            ProcessPoolExecutor(max_workers=args.workers) as pool:
        futs = [pool.submit(run_group, g, str(runs)) for g in todo]
        done = 0
        update("points", 0, n)
        for fut in as_completed(futs):
            rows = fut.result()
            done += len(rows)
            failed += sum(r.get("status") != "ok" for r in rows)
            update("points", done, n, note=rows[-1]["id"])
    if not failed and all(_row_path(runs, p["id"]).exists() for g in groups(BLOCKS) for p in g):
        (runs / "INCOMPLETE").unlink(missing_ok=True)
    print(f"{n} points run into {runs} ({failed} failed)")
    return 1 if failed else 0


# ------------------------------------------------------------------------------------ report


def _rows(runs: Path, failed: bool = False) -> list[dict]:
    """The finished points' rows: those that ran (``ok``), or with ``failed`` those that stopped
    with an error (their ``status`` says which)."""
    rows = []
    for path in sorted((runs / "rows").glob("*.json")):
        r = json.loads(path.read_text())
        if (r.get("status") == "ok") != failed:
            rows.append(r)
    return rows


def bracket(by_alpha: dict, holds) -> dict:
    """alpha* as a bracket: the last alpha that fails and the first that holds, an alpha holding
    when most of its seeds do (``holds(row)``). ``by_alpha``: {alpha: [rows]}.

    Returns {"lo", "hi", "text", "counts", "monotone"}: ``lo`` None when every alpha holds
    (alpha* below the smallest), ``hi`` None when none does (above the largest)."""
    alphas = sorted(by_alpha)
    counts = {a: (sum(bool(holds(r)) for r in by_alpha[a]), len(by_alpha[a])) for a in alphas}
    held = [2 * k > n for k, n in (counts[a] for a in alphas)]
    first = next((i for i in range(len(alphas)) if all(held[i:])), None)
    monotone = held == sorted(held)
    lo = alphas[first - 1] if first not in (None, 0) else (alphas[-1] if first is None else None)
    hi = alphas[first] if first is not None else None
    if hi is None:
        text = f"above {lo:g}"
    elif lo is None:
        text = f"below {hi:g}"
    else:
        text = f"{lo:g}-{hi:g}"
    if not monotone:
        text += " (not monotone)"
    return {"lo": lo, "hi": hi, "text": text, "counts": counts, "monotone": monotone}


MEASURES = {
    "landed verdict": lambda r: r.get("stable_landed") is True,
    "end-of-test verdict": lambda r: r.get("stable") is True,
    "landed f >= 0.5": lambda r: (r.get("cluster_landed") or 0.0) >= 0.5,
}


def _level(r) -> tuple:
    return (LEVEL_OF.get(r["_block"], r["_block"]), r["_scale"], r["_law"], r["_drive"])


def _num(v, fmt="{:.2f}"):
    return "" if v is None else fmt.format(float(v))


def cmd_report(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sys.path.insert(0, str(ROOT))
    from rodwarp.rodset.files import save_figure, write_text

    runs = Path(args.runs)
    rows = _rows(runs)
    if not rows:
        raise SystemExit(f"error: no finished points in {runs}/rows; run `alpha_star_controls.py run --runs {runs}`")
    OUT.mkdir(parents=True, exist_ok=True)
    # every row, flat
    keys = ["id", "_block", "_scale", "_law", "_drive", "alpha", "seed", "n_rods", "length", "gravity", "freq",
            "amplitude", "a_over_g", "throw_height", "cycles_tested", "test_duration_s", "height_kept",
            "largest_cluster_fraction", "persistence", "stable", "height_kept_landed", "cluster_landed",
            "persistence_landed", "stable_landed", "contacts_per_rod", "rods_left", "cv_e", "wall_s"]
    lines = [",".join(k.lstrip("_") for k in keys)]
    for r in sorted(rows, key=lambda r: (r["_block"], r["_drive"], r["alpha"], r["seed"])):
        lines.append(",".join("" if r.get(k) is None else str(r.get(k)) for k in keys))
    write_text(OUT / "results.csv", "\n".join(lines) + "\n")

    # brackets per level (block family, scale, law, drive)
    levels: dict = {}
    for r in rows:
        levels.setdefault(_level(r), []).append(r)
    table = []
    for key in sorted(levels, key=lambda k: (list(BLOCK_NAMES).index(k[0]) if k[0] in BLOCK_NAMES else 99,
                                             ALL_DRIVES.index(k[3]))):
        rs = levels[key]
        by_alpha: dict = {}
        for r in rs:
            by_alpha.setdefault(float(r["alpha"]), []).append(r)
        entry = {"block": key[0], "scale": key[1], "law": key[2], "drive": key[3], "rows": rs,
                 "factor": BLOCK_NAMES[key[0]].factor if key[0] in BLOCK_NAMES else "",
                 "a_over_l": DRIVES[key[3]][0], "ag": DRIVES[key[3]][1],
                 "throw": throw_height(*DRIVES[key[3]]), "wall": sum(float(r["wall_s"]) for r in rs),
                 "by_alpha": by_alpha, "b": {m: bracket(by_alpha, fn) for m, fn in MEASURES.items()}}
        table.append(entry)

    def counts(b):
        return ", ".join(f"{a:g}: {k}/{n}" for a, (k, n) in b["counts"].items())

    csv = ["factor,scale,law,drive,A_over_l,a_over_g,throw_height,alphas,seeds_per_alpha,"
           "landed_lo,landed_hi,landed_stable,end_lo,end_hi,end_stable,f05_lo,f05_hi,point_time_s"]
    for t in table:
        b, e, f = (t["b"][m] for m in MEASURES)
        csv.append(",".join(str(x) for x in (
            t["factor"], t["scale"], f'"{t["law"]}"', f'"{t["drive"]}"', t["a_over_l"], t["ag"], t["throw"],
            " ".join(f"{a:g}" for a in sorted(t["by_alpha"])),
            " ".join(str(len(t["by_alpha"][a])) for a in sorted(t["by_alpha"])),
            b["lo"] or "", b["hi"] or "", f'"{counts(b)}"', e["lo"] or "", e["hi"] or "", f'"{counts(e)}"',
            f["lo"] or "", f["hi"] or "", f"{t['wall']:.0f}")))
    write_text(OUT / "brackets.csv", "\n".join(csv) + "\n")

    md = ["# alpha* with equal cycles and landed measures (issue 51)", "",
          f"Generated by `python scripts/alpha_star_controls.py report --runs RUNS` from {len(rows)} points. "
          f"Every test lasts {CYCLES} drive cycles, sampled {SAMPLES_PER_CYCLE} times a cycle; the landed "
          "measures are h and f at each cycle's lowest centroid, averaged over the last 5 cycles, with the "
          "persistence over all cycles (docs/verdict.md, \"The landed phase\"). An alpha holds when most of its "
          "seeds are stable; alpha* is the bracket (last alpha that fails - first that holds), with the stable "
          "seeds per alpha. Contact law exact (Signorini and the Coulomb cone, mu = 0.2, rolling rods) unless "
          "named; N = round(5.4 alpha) unless named; rod model by the sag rule; the paper protocol's entangling "
          "(A_e / l = 0.05, a_e / g = 19.7, 50 cycles) at each scale: paper l = 1 m, g = 10 m/s^2; lab "
          "l = 50 mm, g = 9.81 m/s^2. Point time: the sum of the points' wall times (2-core Intel Xeon, two "
          "points at a time beside other jobs).", "",
          "| factor | scale | law | drive (A, a/g) | throw height (A omega)^2/(g l) | alpha* landed verdict "
          "(stable seeds per alpha) | alpha* end-of-test verdict (stable seeds) | alpha* landed f >= 0.5 | "
          "point time (s) |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for t in table:
        b, e, f = (t["b"][m] for m in MEASURES)
        md.append(f"| {t['factor']} | {t['scale']} | {t['law']} | {t['drive']} | {t['throw']:.3g} | "
                  f"**{b['text']}** ({counts(b)}) | {e['text']} ({counts(e)}) | {f['text']} | {t['wall']:.0f} |")
    md += ["", "## Per alpha: landed and end-of-test measures (medians over seeds, [min, max])", "",
           "| scale | law | drive | alpha | seeds | rod model | landed h | landed f | landed persistence | end h | "
           "end f | end persistence | wall per point (s) |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]

    def rng(rs, k):
        v = sorted(float(r[k]) for r in rs if r.get(k) is not None)
        if not v:
            return ""
        med = v[len(v) // 2] if len(v) % 2 else 0.5 * (v[len(v) // 2 - 1] + v[len(v) // 2])
        return f"{med:.2f} [{v[0]:.2f}, {v[-1]:.2f}]"

    for t in table:
        for a in sorted(t["by_alpha"]):
            rs = t["by_alpha"][a]
            model = _rod_model(runs, rs[0])
            md.append(f"| {t['scale']} | {t['law']} | {t['drive']} | {a:g} | {len(rs)} | {model} | "
                      f"{rng(rs, 'height_kept_landed')} | {rng(rs, 'cluster_landed')} | "
                      f"{rng(rs, 'persistence_landed')} | {rng(rs, 'height_kept')} | "
                      f"{rng(rs, 'largest_cluster_fraction')} | {rng(rs, 'persistence')} | {rng(rs, 'wall_s')} |")
    bad = _rows(runs, failed=True)
    if bad:
        md += ["", "## Points that stopped (the engine refused to go on and said why)", "",
               "| point | law | drive | status | wall (s) |", "| --- | --- | --- | --- | --- |"]
        md += [f"| {r['id']} | {r['_law']} | {r['_drive']} | {r['status']} | {float(r['wall_s']):.0f} |" for r in bad]
    total = sum(float(r["wall_s"]) for r in rows + bad)
    md += ["", f"Total point time: {total:.0f} s ({total / 3600:.2f} CPU-hours) over {len(rows) + len(bad)} points.", ""]
    by_block: dict = {}
    for r in rows + bad:
        by_block[r["_block"]] = by_block.get(r["_block"], 0.0) + float(r["wall_s"])
    md += ["| block | what | points | point time (s) |", "| --- | --- | --- | --- |"]
    for name, t in sorted(by_block.items(), key=lambda kv: list(BLOCK_NAMES).index(kv[0])):
        n = sum(r["_block"] == name for r in rows + bad)
        md.append(f"| {name} | {BLOCK_NAMES[name].why} | {n} | {t:.0f} |")
    md.append("")
    missing = [p["id"] for g in groups(BLOCKS) for p in g if not _row_path(runs, p["id"]).exists()]
    if missing:
        blocks_missing = sorted({m.split("_alpha")[0] for m in missing}, key=list(BLOCK_NAMES).index)
        md += [f"Not run yet: {len(missing)} points of the blocks {', '.join(blocks_missing)} "
               "(`python scripts/alpha_star_controls.py plan` lists them).", ""]
    write_text(OUT / "controls.md", "\n".join(md) + "\n")
    _figures(plt, table, save_figure)
    _landed_cycles(plt, runs, table, save_figure)
    print((OUT / "controls.md").read_text())
    return 0


def _rod_model(runs: Path, row: dict) -> str:
    try:
        s = json.loads((runs / "points" / row.get("_folder", row["id"]) / "summary.json").read_text())
        return f"{s['rod_model']}" + (f" ({s['parameters']['vertices']} v)" if s["rod_model"] == "elastic" and
                                      s["parameters"].get("vertices") else "")
    except (OSError, KeyError, ValueError):
        return ""


#: the amplitudes, smallest first, and their markers on the a/g axis
A_ORDER = (0.001, 0.05, 0.5)
A_MARKERS = ("o", "^", "D")


def _figures(plt, table, save_figure) -> None:
    """drive_map.png: the landed outcome of each alpha against the throw height and against a/g
    (exact law); brackets.png: alpha* per level."""
    exact = [t for t in table if t["law"] == "exact" and t["factor"] in ("drive", "baseline")]
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    markers = {"lab": "o", "paper": "s"}
    for t in exact:
        for a, rs in t["by_alpha"].items():
            k = sum(MEASURES["landed verdict"](r) for r in rs)
            frac = k / len(rs)
            f = sorted(float(r["cluster_landed"]) for r in rs if r.get("cluster_landed") is not None)
            ia = A_ORDER.index(t["a_over_l"])
            for col, x in ((0, t["throw"]), (1, t["ag"])):
                # left: marker = scale; right: marker = amplitude, offset so that drives of one
                # a/g sit side by side
                if col == 0:
                    jitter, mk = 1.0 + 0.06 * (list(markers).index(t["scale"]) - 0.5), markers[t["scale"]]
                else:
                    jitter = (1.0 + 0.1 * (ia - 1)) * (1.0 + 0.03 * (list(markers).index(t["scale"]) - 0.5))
                    mk = A_MARKERS[ia]
                edge = 1.6 if t["scale"] == "paper" else 0.5
                axes[0, col].scatter([x * jitter], [a], c=[[1 - frac, frac, 0.2]], marker=mk,
                                     s=90, edgecolors="k", linewidths=edge)
                axes[0, col].annotate(f"{k}/{len(rs)}", (x * jitter, a), textcoords="offset points", xytext=(5, 4),
                                      fontsize=6)
                if f:
                    colour = f"C{[25, 50, 100, 200].index(int(a))}" if int(a) in (25, 50, 100, 200) else "C5"
                    axes[1, col].errorbar([x * jitter], [f[len(f) // 2]], yerr=[[f[len(f) // 2] - f[0]],
                                                                                 [f[-1] - f[len(f) // 2]]],
                                          fmt=mk, color=colour, mec="k" if t["scale"] == "paper" else colour,
                                          capsize=3, ms=6)
    for col, label in ((0, "throw height (A omega)^2 / (g l) = (a/g)(A/l) [rod lengths]"), (1, "a/g [dimensionless]")):
        for row in (0, 1):
            axes[row, col].set_xscale("log")
            axes[row, col].set_xlabel(label)
        axes[0, col].set_yscale("log")
        axes[0, col].set_ylabel("alpha = l / d")
        axes[0, col].set_yticks([25, 50, 100, 200])
        axes[0, col].set_yticklabels(["25", "50", "100", "200"])
        axes[0, col].yaxis.set_minor_formatter(plt.NullFormatter())
        axes[0, col].set_ylim(20, 260)
        axes[1, col].set_ylabel("landed f, last 5 cycles (median, range over seeds)")
        axes[1, col].axhline(0.8, color="grey", ls="--", lw=1)
        axes[1, col].axhline(0.5, color="grey", ls=":", lw=1)
    from matplotlib.lines import Line2D

    axes[0, 0].legend(handles=[Line2D([], [], marker=m, ls="", color="grey", label=f"{s} scale")
                               for s, m in markers.items()], fontsize=8, loc="lower right")
    axes[1, 0].legend(handles=[Line2D([], [], marker="o", ls="", color=f"C{i}", label=f"alpha {a}")
                               for i, a in enumerate((25, 50, 100, 200))], fontsize=8, loc="lower left")
    axes[1, 1].legend(handles=[Line2D([], [], marker=m, ls="", color="grey", label=f"A = l/{round(1 / a)}")
                               for a, m in zip(A_ORDER, A_MARKERS)] +
                      [Line2D([], [], marker="o", ls="", mfc="grey", mec="k", mew=1.6, label="paper scale (thick edge)")],
                      fontsize=8, loc="lower left")
    axes[0, 0].set_title("stable seeds (landed verdict): green all, red none; marker: scale", fontsize=10)
    axes[0, 1].set_title("the same against a/g; marker: amplitude", fontsize=10)
    fig.suptitle(f"The drive map: exact law, {CYCLES} cycles per test, landed measures", fontsize=11)
    fig.tight_layout()
    save_figure(fig, OUT / "drive_map.png")
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(10, 0.45 * len(table) + 2))
    for i, t in enumerate(table):
        y = len(table) - 1 - i
        for j, (m, col) in enumerate(zip(MEASURES, ("C0", "C1", "C2"))):
            b = t["b"][m]
            yy = y + (1 - j) * 0.2
            lo, hi = b["lo"], b["hi"]
            if lo is not None and hi is not None:
                ax.plot([lo, hi], [yy, yy], "-", color=col, lw=3)
            elif hi is not None:
                ax.annotate("", xy=(hi / 1.6, yy), xytext=(hi, yy), arrowprops=dict(arrowstyle="-|>", color=col))
            elif lo is not None:
                ax.annotate("", xy=(lo * 1.6, yy), xytext=(lo, yy), arrowprops=dict(arrowstyle="-|>", color=col))
    ax.set_yticks(range(len(table)))
    ax.set_yticklabels([f"{t['scale']}, {t['law']}, {t['drive']}" + (", N 540" if "N540" in t["block"] else "")
                        for t in reversed(table)], fontsize=8)
    ax.axvline(100, color="grey", ls="-", lw=1)
    ax.set_xscale("log")
    ax.set_xlim(8, 400)
    ax.set_xlabel("alpha* bracket (last alpha that fails - first that holds); arrows: beyond the alphas run; "
                  "grey: the paper's ~100", fontsize=9)
    from matplotlib.lines import Line2D

    ax.legend(handles=[Line2D([], [], color=c, lw=3, label=m) for m, c in zip(MEASURES, ("C0", "C1", "C2"))],
              fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, frameon=False)
    ax.set_title(f"alpha* brackets, {CYCLES} cycles per test", fontsize=10)
    fig.tight_layout()
    save_figure(fig, OUT / "brackets.png")
    plt.close(fig)


def _landed_cycles(plt, runs: Path, table, save_figure) -> None:
    """landed_cycles.png: the landed f and h of every cycle of every run, one panel per drive of
    the lab scale's exact law (a pile that stands, one that comes apart slowly, one that falls
    at once), one colour per alpha."""
    exact = [t for t in table if t["law"] == "exact" and t["scale"] == "lab" and t["factor"] == "drive"]
    if not exact:
        return
    fig, axes = plt.subplots(2, len(exact), figsize=(3.0 * len(exact), 6), sharey="row", squeeze=False)
    colours = {25: "C0", 50: "C1", 100: "C2", 200: "C3"}
    for j, t in enumerate(exact):
        for a, rs in sorted(t["by_alpha"].items()):
            for r in rs:
                try:
                    s = json.loads((runs / "points" / r.get("_folder", r["id"]) / "summary.json").read_text())
                except (OSError, ValueError):
                    continue
                pc = (s.get("landed") or {}).get("per_cycle") or {}
                if not pc.get("cycle"):
                    continue
                for i, k in enumerate(("largest_cluster_fraction", "height_kept")):
                    axes[i, j].plot(pc["cycle"], pc[k], color=colours.get(int(a), "C5"), lw=0.8, alpha=0.8)
        axes[0, j].set_title(t["drive"], fontsize=9)
        axes[1, j].set_xlabel("cycle N")
        axes[0, j].axhline(0.8, color="grey", ls="--", lw=0.8)
        axes[1, j].axhline(0.26, color="grey", ls="--", lw=0.8)
    axes[0, 0].set_ylabel("landed f")
    axes[1, 0].set_ylabel("landed h")
    from matplotlib.lines import Line2D

    axes[0, 0].legend(handles=[Line2D([], [], color=c, label=f"alpha {a}") for a, c in colours.items()], fontsize=7)
    fig.suptitle("Each cycle's landed packing, lab scale, exact law: one line per seed; dashed: the verdict's "
                 "thresholds", fontsize=10)
    fig.tight_layout()
    save_figure(fig, OUT / "landed_cycles.png")
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("plan", help="list the blocks, their drives and test lengths")
    p.add_argument("--only", help="comma-separated block names")
    p = sub.add_parser("run", help="run (or go on with) the study")
    p.add_argument("--runs", required=True, help="folder of the runs (created)")
    p.add_argument("--workers", type=int, default=2, help="points at a time (default 2)")
    p.add_argument("--only", help="comma-separated block names (default: every block, in order)")
    p.add_argument("--quiet", action="store_true")
    p = sub.add_parser("report", help="tables and charts from the finished points")
    p.add_argument("--runs", required=True)
    args = ap.parse_args(argv)
    if getattr(args, "workers", 1) < 1:
        ap.error("--workers must be 1 or more")
    return {"plan": cmd_plan, "run": cmd_run, "report": cmd_report}[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
