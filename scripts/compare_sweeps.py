"""Compare the verdict of two or more sweeps point by point (same alpha and seed): a table and a figure.

Used for "what the physics changes" (docs/transition.md): the g = 10, a/g = 1 rows with rolling
rods against the same rows with rolling locked (``--no-rolling``).

    python scripts/compare_sweeps.py rolling=runs/g10 locked=runs/g10_norolling \
        --out benchmarks/results/transition/rolling_vs_locked

Writes OUT.md (one row per alpha and seed present in every sweep: height kept, f, rods left,
persistence, Z, cv_e and the verdict of each) and OUT.png (those measures against alpha, one
marker per sweep, the verdict's thresholds drawn).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

MEASURES = (("height_kept", "height kept h"), ("largest_cluster_fraction", "f (largest cluster)"),
            ("persistence", "persistence tau"), ("rods_left", "rods left"), ("contacts_per_rod", "Z"),
            ("cv_e", "cv_e (final packing)"))


def _rows(folder: Path) -> dict:
    from rodwarp.experiments import read_results

    out = {}
    for r in read_results(folder / "results.csv"):
        if r.get("status") == "ok":
            out[(float(r["alpha"]), int(r["seed"]))] = r
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweeps", nargs="+", help="LABEL=FOLDER (a sweep folder holding results.csv)")
    ap.add_argument("--out", required=True, help="output path without suffix (.md and .png are written)")
    a = ap.parse_args(argv)
    try:
        named = [(s.split("=", 1)[0], Path(s.split("=", 1)[1])) for s in a.sweeps]
    except IndexError:
        print("error: give each sweep as LABEL=FOLDER", file=sys.stderr)
        return 2
    data = {label: _rows(folder) for label, folder in named}
    keys = sorted(set.intersection(*(set(d) for d in data.values())))
    if not keys:
        print("error: the sweeps share no (alpha, seed) point with results", file=sys.stderr)
        return 2
    from rodwarp.experiments import DEFAULT_THRESHOLDS
    from rodwarp.rodset.files import save_figure, write_text

    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    head = "| alpha | seed | sweep | " + " | ".join(m[1] for m in MEASURES) + " | verdict |"
    lines = [head, "|" + "---|" * (len(MEASURES) + 4)]
    for k in keys:
        for label, _ in named:
            r = data[label][k]
            vals = " | ".join(f"{float(r[m]):.3g}" if r.get(m) not in (None, "") else "" for m, _ in MEASURES)
            verdict = "stable" if str(r["stable"]).lower() == "true" else "unstable"
            lines.append(f"| {k[0]:g} | {k[1]} | {label} | {vals} | {verdict} |")
    write_text(out.with_suffix(".md"), "\n".join(lines) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    thr = {"height_kept": DEFAULT_THRESHOLDS.height_kept, "largest_cluster_fraction": DEFAULT_THRESHOLDS.cluster,
           "persistence": DEFAULT_THRESHOLDS.persistence}
    fig, axs = plt.subplots(2, 3, figsize=(11, 6))
    for ax, (m, title) in zip(axs.ravel(), MEASURES):
        for j, (label, _) in enumerate(named):
            xs = [k[0] * (1 + 0.04 * (j - (len(named) - 1) / 2)) for k in keys]
            ys = [float(data[label][k][m]) if data[label][k].get(m) not in (None, "") else math.nan for k in keys]
            ax.plot(xs, ys, "os^v"[j % 4], label=label, ms=6, alpha=0.8)
        if m in thr:
            ax.axhline(thr[m], color="tab:red", ls=":", lw=1)
        ax.set_xscale("log")
        ax.set_xlabel("alpha")
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    axs[0, 0].legend(fontsize=8)
    fig.suptitle(" vs ".join(label for label, _ in named) + " (red: the verdict's thresholds)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, out.with_suffix(".png"))
    plt.close(fig)
    print(f"wrote {out.with_suffix('.md')} and {out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
