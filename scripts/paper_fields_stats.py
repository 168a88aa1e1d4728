"""Statistics of the paper authors' experimental fields (X-ray CT packings, alpha x strain).

For every ``alpha{A}_epsilon{E}.npz`` in the data folder: load it with ``Fields.load``, run
``field_statistics`` (outlier bound Q3 + 1.5 IQR, 26-connected tangles) and collect the
coefficient of variation sigma_e / mu_e, the outlier bound, the tangles and percolation.

    python scripts/paper_fields_stats.py --data PAPER_FIELDS_FOLDER [--out benchmarks/results]

Writes OUT/paper_fields.json, OUT/paper_fields.md (table and the trend against alpha),
OUT/paper_fields_cv_e.png, OUT/paper_fields_tangles.png and a tangle map of the
alpha = 100, epsilon = 0 packing, OUT/paper_fields_tangles_alpha100_eps00.png.
"""

from __future__ import annotations

import argparse
import hashlib
import re
import shlex
import subprocess
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_DATA = None  # the folder of the authors' published fields (alpha*_epsilon*.npz): --data
DEFAULT_OUT = ROOT / "benchmarks" / "results"
NAME = re.compile(r"alpha(\d+)_epsilon(\d+)\.npz$")
AXES = ("x", "y", "z")


def _git_commit() -> str | None:
    try:
        out = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=ROOT, capture_output=True,
                             text=True, timeout=10).stdout.strip()
        return out or None
    except (OSError, subprocess.SubprocessError):
        return None


def _versions() -> dict:
    from rodwarp._util import versions

    return {**versions("matplotlib"), "git": _git_commit()}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def analyse(path: Path, alpha: int, epsilon: float) -> tuple[dict, object, dict]:
    from rodwarp.analysis import Fields, field_statistics

    f = Fields.load(path)
    s = field_statistics(f, method="q3", connectivity=26)
    # the text's Q1 + 1.5 IQR bound, kept only to show how much the choice matters
    q1 = field_statistics(f, method="q1", connectivity=26)
    row = {
        "file": path.name,
        "sha256": _sha256(path),
        "alpha": alpha,
        "epsilon": epsilon,
        "shape_zyx": s["shape"],
        "radius": s["radius"],
        "spacing": s["spacing"],
        "units": s["units"],
        "system_size": s["system_size"],
        "n_valid_voxels": s["n_valid_voxels"],
        "valid_fraction": s["valid_fraction"],
        "mean_e": s["mean_e"],
        "std_e": s["std_e"],
        "cv_e": s["cv_e"],
        "q1_e": s["q1_e"],
        "q3_e": s["q3_e"],
        "e_lb": s["e_lb"],
        "outlier_fraction": s["outlier_fraction"],
        "n_tangles": s["n_tangles"],
        "largest_tangle_share": s["largest_tangle_share"],
        "largest_tangle_xi_over_L": s["largest_tangle_extent"],
        "largest_tangle_xi": s["largest_tangle_xi"],
        "percolates": s["percolates"],
        "percolating_axes": s["percolating_axes"],
        "q1_variant": {
            "e_lb": q1["e_lb"],
            "outlier_fraction": q1["outlier_fraction"],
            "n_tangles": q1["n_tangles"],
            "largest_tangle_share": q1["largest_tangle_share"],
            "largest_tangle_xi_over_L": q1["largest_tangle_extent"],
            "percolating_axes": q1["percolating_axes"],
        },
    }
    return row, f, s


# ----------------------------------------------------------------------------------------------
# trend text: generated from the numbers so that it stays true when the data change
# ----------------------------------------------------------------------------------------------

def _trend(values) -> str:
    d = np.diff(np.asarray(values, dtype=float))
    if np.all(d > 0):
        return "increasing"
    if np.all(d < 0):
        return "decreasing"
    return "not monotonic"


def _fmt_list(values, fmt="{:.2f}") -> str:
    return ", ".join(fmt.format(v) for v in values)


def trend_text(rows: list[dict]) -> list[str]:
    alphas = sorted({r["alpha"] for r in rows})
    strains = sorted({r["epsilon"] for r in rows})
    by = {(r["alpha"], r["epsilon"]): r for r in rows}
    grid_ok = all((a, e) in by for a in alphas for e in strains)
    if not grid_ok or len(alphas) < 2:
        return ["The files do not form a full alpha x epsilon grid; no trend is stated."]
    alist = ", ".join(str(a) for a in alphas)
    out = []

    # 1. order parameter
    cv = {e: [by[a, e]["cv_e"] for a in alphas] for e in strains}
    trends = {e: _trend(cv[e]) for e in strains}
    inc = [e for e in strains if trends[e] == "increasing"]
    e0 = strains[0]
    if len(inc) == len(strains):
        head = "sigma_e/mu_e increases monotonically with alpha at every strain"
    elif inc:
        head = ("sigma_e/mu_e increases monotonically with alpha only at epsilon = "
                + ", ".join(f"{e:.2f}" for e in inc) + "; at the other strains it is not monotonic")
    else:
        head = "sigma_e/mu_e is not monotonic in alpha at any strain"
    above = [(a, e) for a in alphas for e in strains if by[a, e]["cv_e"] >= 1.0]
    tail = ("; it reaches 1 only for " + ", ".join(f"alpha = {a} at epsilon = {e:.2f}" for a, e in above)
            if above else "; it stays below 1 everywhere")
    out.append(f"{head} (epsilon = {e0:.2f}: {_fmt_list(cv[e0])} for alpha = {alist}){tail}.")

    # 2. largest tangle
    span = {(a, e): max(by[a, e]["largest_tangle_xi_over_L"].values()) for a in alphas for e in strains}
    mean_span = [float(np.mean([span[a, e] for e in strains])) for a in alphas]
    winners = {e: max(alphas, key=lambda a: span[a, e]) for e in strains}
    n_perc = sum(by[a, e]["percolates"] for a in alphas for e in strains)
    win_alphas = sorted(set(winners.values()))
    if len(win_alphas) == 1:
        w = f"the largest tangle is biggest at alpha = {win_alphas[0]} at every strain"
    else:
        w = "the alpha with the biggest largest tangle changes with strain (" + ", ".join(
            f"epsilon = {e:.2f}: alpha = {winners[e]}" for e in strains) + ")"
    perc = ("no tangle percolates in any packing" if n_perc == 0 else
            f"{n_perc} of {len(rows)} packings have a percolating tangle")
    out.append(f"With e_lb = Q3 + 1.5 IQR and 26-connectivity, {w} (largest xi/L over the axes, mean over "
               f"strains: {_fmt_list(mean_span)} for alpha = {alist}, {_trend(mean_span)} in alpha), and {perc}.")

    # 3. outliers and tangle counts
    of = [float(np.mean([by[a, e]["outlier_fraction"] for e in strains])) for a in alphas]
    nt = [float(np.mean([by[a, e]["n_tangles"] for e in strains])) for a in alphas]
    out.append(f"The outlier fraction (mean over strains: {_fmt_list([100 * v for v in of])} % for alpha = {alist}) "
               f"is {_trend(of)} in alpha, and the number of tangles ({_fmt_list(nt, '{:.0f}')}) is "
               f"{_trend(nt)}.")
    return out


def q1_note(rows: list[dict]) -> str:
    spans = [max(r["q1_variant"]["largest_tangle_xi_over_L"].values()) for r in rows]
    perc = [r for r in rows if r["q1_variant"]["percolating_axes"]]
    who = ", ".join(f"alpha = {r['alpha']}, epsilon = {r['epsilon']:.2f} ({','.join(r['q1_variant']['percolating_axes'])})"
                    for r in perc)
    return (f"Note: with the text's bound Q1 + 1.5 IQR the outlier set is much larger and the largest tangle spans "
            f"{min(spans):.2f}-{max(spans):.2f} of the system along some axis in every packing"
            + (f"; it percolates in {who}" if perc else "")
            + ", so that bound does not separate the aspect ratios (the numbers are in paper_fields.json, `q1_variant`).")


def markdown(rows: list[dict], meta: dict) -> str:
    lines = [
        "# Statistics of the paper's experimental fields",
        "",
        f"Generated by `{meta['command']}` on {meta['date']} (rodwarp `stats.field_statistics`, "
        "outlier bound e_lb = Q3 + 1.5 IQR with linear-interpolation quartiles over the valid voxels, "
        "tangles = 26-connected clusters of voxels with e > e_lb). Data: the authors' X-ray CT fields "
        "(the authors' published paper-fields, MIT licence); lengths in CT voxels. xi/L: bounding box of the "
        "largest tangle over the bounding box of the valid voxels; a tangle percolates along an axis when it "
        "touches both opposite faces of that box.",
        "",
        "| alpha | epsilon | sigma_e/mu_e | mean e | e_lb | outlier fraction | tangles | largest share "
        "| largest xi/L (x, y, z) | percolates |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for r in rows:
        x = r["largest_tangle_xi_over_L"]
        perc = ("yes (" + ",".join(r["percolating_axes"]) + ")") if r["percolates"] else "no"
        lines.append(f"| {r['alpha']} | {r['epsilon']:.2f} | {r['cv_e']:.3f} | {r['mean_e']:.2f} | {r['e_lb']:.1f} "
                     f"| {100 * r['outlier_fraction']:.2f} % | {r['n_tangles']} | {100 * r['largest_tangle_share']:.2f} % "
                     f"| {x['x']:.2f}, {x['y']:.2f}, {x['z']:.2f} | {perc} |")
    lines += ["", "## Trend against alpha", "", " ".join(trend_text(rows)), "", q1_note(rows), ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# charts
# ----------------------------------------------------------------------------------------------

def _lines_by_strain(ax, rows, key):
    for i, e in enumerate(sorted({r["epsilon"] for r in rows})):
        pts = sorted((r["alpha"], key(r)) for r in rows if r["epsilon"] == e)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=f"C{i}", label=f"epsilon = {e:.2f}")


def chart_cv(rows, path: Path) -> Path:
    from matplotlib.figure import Figure

    from rodwarp.rodset.files import save_figure

    fig = Figure(figsize=(6, 4.2), layout="constrained")
    ax = fig.subplots()
    _lines_by_strain(ax, rows, lambda r: r["cv_e"])
    ax.axhline(1.0, color="0.5", ls=":", lw=1, label="sigma_e/mu_e = 1")
    ax.set(xlabel="aspect ratio alpha", ylabel="sigma_e / mu_e",
           title="coefficient of variation of e (authors' CT fields)")
    ax.set_xticks(sorted({r["alpha"] for r in rows}))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def chart_tangles(rows, path: Path) -> Path:
    from matplotlib.figure import Figure

    from rodwarp.rodset.files import save_figure

    fig = Figure(figsize=(15, 3.8), layout="constrained")
    axs = fig.subplots(1, 4)
    alphas = sorted({r["alpha"] for r in rows})
    for ax, axis in zip(axs[:3], AXES):
        _lines_by_strain(ax, rows, lambda r, axis=axis: r["largest_tangle_xi_over_L"][axis])
        ax.set(xlabel="alpha", ylabel=f"xi_{axis} / L_{axis}", ylim=(0, 1.05),
               title=f"largest tangle, {axis} extent")
    _lines_by_strain(axs[3], rows, lambda r: r["n_tangles"])
    axs[3].set(xlabel="alpha", ylabel="number of tangles", title="tangles (26-connected, Q3 + 1.5 IQR)")
    for ax in axs:
        ax.set_xticks(alphas)
        ax.grid(alpha=0.3)
    axs[0].legend(fontsize=8)
    return save_figure(fig, path)


# ----------------------------------------------------------------------------------------------

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="folder of the authors' alpha*_epsilon*.npz fields")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="folder for the results")
    args = ap.parse_args(argv)

    from rodwarp.analysis import plot_tangles
    from rodwarp.errors import RodwarpError
    from rodwarp.rodset.files import write_json, write_text

    files = []
    for p in sorted(args.data.glob("*.npz")):
        m = NAME.search(p.name)
        if m:
            files.append((int(m.group(1)), int(m.group(2)) / 100.0, p))
    if not files:
        raise RodwarpError(f"no alpha*_epsilon*.npz files in '{args.data}'")
    files.sort()

    rows = []
    for alpha, eps, p in files:
        row, f, s = analyse(p, alpha, eps)
        rows.append(row)
        x = row["largest_tangle_xi_over_L"]
        print(f"alpha {alpha:3d} eps {eps:.2f}: grid {tuple(row['shape_zyx'])} valid {row['valid_fraction']:.3f} "
              f"mean e {row['mean_e']:.2f} cv_e {row['cv_e']:.3f} e_lb {row['e_lb']:.1f} "
              f"outliers {100 * row['outlier_fraction']:.2f}% tangles {row['n_tangles']} "
              f"largest xi/L ({x['x']:.2f}, {x['y']:.2f}, {x['z']:.2f}) percolates {row['percolates']}", flush=True)
        if alpha == 100 and eps == 0.0:
            plot_tangles(f, None, s, args.out / "paper_fields_tangles_alpha100_eps00.png")

    meta = {
        "command": shlex.join(["python", *sys.argv]) if argv is None else shlex.join(["python", __file__, *argv]),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "versions": _versions(),
        # the folder's name, not its path on this machine: each file is identified by its sha256 below
        "data": f"{Path(args.data).name} (given with --data)",
        "settings": {"outlier_method": "q3", "connectivity": 26,
                     "xi_over_L": "largest tangle bounding box / bounding box of the valid voxels",
                     "share": "tangle voxels / valid voxels"},
    }
    write_json(args.out / "paper_fields.json", {**meta, "trend": trend_text(rows), "files": rows})
    write_text(args.out / "paper_fields.md", markdown(rows, meta))
    chart_cv(rows, args.out / "paper_fields_cv_e.png")
    chart_tangles(rows, args.out / "paper_fields_tangles.png")
    print("\n".join(trend_text(rows)))
    print(f"wrote {args.out}/paper_fields.json, .md, _cv_e.png, _tangles.png, _tangles_alpha100_eps00.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
