"""alpha* against each factor the paper's simulation may have set differently (issue 30).

Reads the ``results.csv`` of the sweeps listed in :data:`LEVELS` (each a factor and one of its
levels: the number of rods, the test drive; the contact law when it is built) and computes, on
the same rows, alpha* by three measures:

* ``verdict``: where the fraction of seeds judged stable (docs/verdict.md) crosses 1/2;
* ``f``: where the seed-mean largest contact cluster f crosses 0.5 (the paper's Fig. 4H measure);
* ``h``: where the fraction of seeds that keep their height (h >= the verdict's 0.26) crosses 1/2.

Each is reported as the bracket of alphas between which it crosses 1/2 (the interpolated
crossing is computed, for the CSV, but not shown: three seeds do not place it inside the bracket). Writes ``benchmarks/results/transition/factors/alpha_star_factors.csv``,
``alpha_star_factors.md`` (the table, with the point time of each sweep) and
``alpha_star_factors.png``.

    python scripts/alpha_star_factors.py
"""

from __future__ import annotations

import random
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TRANSITION = ROOT / "benchmarks" / "results" / "transition"
OUT = TRANSITION / "factors"

#: (factor, level, folders holding results.csv, alphas kept (None: all), what the level is);
#: the figure's label of each level is :data:`SHORT`
LEVELS = [
    ("baseline", "exact law, N = 5.4 alpha, A = 1 mm, a/g = 1", [TRANSITION], None,
     "the protocol of docs/transition.md: g = 10, f = 15.92 Hz, 3 seeds"),
    ("number of rods", "N = 540 (box widened: 2.58, 2 and 1.41 wide at alpha 15, 25 and 50)",
     [OUT / "fixedN_alpha15", OUT / "fixedN_alpha25", OUT / "fixedN_alpha50", TRANSITION], (15.0, 25.0, 50.0, 100.0),
     "alpha 100 is the baseline's own N = 540 run; a/g = 1"),
    ("drive", "A = 1 mm (l/1000), a/g = 2.5", [TRANSITION / "g10_ag2.5"], None, "f = 25.2 Hz"),
    ("drive", "A = 50 mm (l/20), a/g = 2.5", [OUT / "drive_l20"], None, "f = 3.559 Hz"),
    ("drive", "A = 500 mm (l/2), a/g = 2.5", [OUT / "drive_l2"], None, "f = 1.125 Hz (the laboratory's drive)"),
    ("contact law", "exact, spin locked (--no-rolling)", [OUT / "exact_locked"], None, "the exact law with "
     "DisMech's centreline friction: separates locking the spin from IMC's smoothing"),
    ("contact law", "IMC, delta = d/10, nu = 1e-4 m/s", [OUT / "imc_nu1e-4"], None, "spin locked, as DisMech"),
    ("contact law", "IMC, delta = d/10, nu = 1e-3 m/s", [OUT / "imc_nu1e-3"], None, "spin locked; DisMech's "
     "examples' nu"),
    ("contact law", "IMC, delta = d/10, nu = 1e-2 m/s", [OUT / "imc_nu1e-2"], None, "spin locked"),
]
SHORT = {"exact law, N = 5.4 alpha, A = 1 mm, a/g = 1": "baseline (N = 5.4 alpha, A = 1 mm, a/g = 1)",
         "N = 540 (box widened: 2.58, 2 and 1.41 wide at alpha 15, 25 and 50)": "N = 540 at every alpha (a/g = 1)",
         "A = 1 mm (l/1000), a/g = 2.5": "drive A = l/1000, a/g = 2.5",
         "A = 50 mm (l/20), a/g = 2.5": "drive A = l/20, a/g = 2.5",
         "A = 500 mm (l/2), a/g = 2.5": "drive A = l/2, a/g = 2.5 (the laboratory's)",
         "exact, spin locked (--no-rolling)": "exact law, spin locked (a/g = 1)",
         "IMC, delta = d/10, nu = 1e-4 m/s": "IMC, nu = 1e-4 m/s (a/g = 1)",
         "IMC, delta = d/10, nu = 1e-3 m/s": "IMC, nu = 1e-3 m/s (a/g = 1)",
         "IMC, delta = d/10, nu = 1e-2 m/s": "IMC, nu = 1e-2 m/s (a/g = 1)"}
#: reference values drawn beside the measured alpha*
REFERENCES = {"rodwarp before (verdict, a/g = 1)": 35.0, "paper (simulation and experiment)": 100.0,
              "acrylic piles stand without walls (Desmond & Weeks)": 35.0}


def _rows(folders, alphas):
    sys.path.insert(0, str(ROOT))
    from rodwarp.experiments._phase import _phase_rows
    from rodwarp.experiments._sweep import read_results

    rows, wall = [], 0.0
    for folder in folders:
        if not (Path(folder) / "results.csv").exists():
            return None, 0.0
        got = _phase_rows(folder)[0]
        if alphas is not None:
            got = [r for r in got if r["alpha"] in alphas]
        if folder == TRANSITION and alphas is not None:
            got = [r for r in got if r["alpha"] not in (25.0, 50.0)]  # N = 540 comes from the other folders
        rows += got
        kept = {r["id"] for r in got}
        wall += sum(float(r.get("wall_s") or 0.0) for r in read_results(Path(folder) / "results.csv")
                    if r.get("id") in kept)
    return rows, wall


def measures(rows, n_boot: int = 400, seed: int = 0) -> dict:
    """alpha* by each measure: {name: (alpha*, err, lo, hi, boot_std, note)}."""
    from rodwarp.experiments._phase import _bracketed
    from rodwarp.experiments._verdict import DEFAULT_THRESHOLDS

    h_min = DEFAULT_THRESHOLDS.height_kept
    by_alpha: dict = {}
    for r in rows:
        by_alpha.setdefault(r["alpha"], []).append(r)
    alphas = sorted(by_alpha)
    value = {"verdict": lambda r: float(r["stable"]), "f": lambda r: r["largest_cluster_fraction"],
             "h": lambda r: float(r["height_kept"] >= h_min)}
    return {k: _bracketed(alphas, by_alpha, fn, random.Random(seed), n_boot) for k, fn in value.items()}


def _fmt(m) -> str:
    """The bracket (the alphas between which the measure crosses 1/2), never an interpolated
    point: with three seeds per alpha the crossing's place inside the bracket is not measured."""
    x, err, lo, hi, boot, note = m
    if x is None:
        return note
    return f"{lo:g}-{hi:g}"


def main() -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sys.path.insert(0, str(ROOT))
    from rodwarp.rodset.files import save_figure, write_text

    OUT.mkdir(parents=True, exist_ok=True)
    table, missing = [], []
    for factor, level, folders, alphas, what in LEVELS:
        rows, wall = _rows(folders, alphas)
        if rows is None:
            missing.append(f"{factor}: {level}")
            continue
        seeds = sorted({int(r["seed"]) for r in rows})
        table.append({"factor": factor, "level": level, "short": SHORT.get(level, level), "what": what, "alphas": sorted({r["alpha"] for r in rows}),
                      "seeds": len(seeds), "points": len(rows), "point_time_s": wall, "m": measures(rows),
                      "stable": {a: sum(r["stable"] for r in rows if r["alpha"] == a) for a in
                                 sorted({r["alpha"] for r in rows})},
                      "n": {a: sum(1 for r in rows if r["alpha"] == a) for a in sorted({r["alpha"] for r in rows})}})
    # CSV
    lines = ["factor,level,alphas,seeds,points,point_time_s," + ",".join(
        f"{k}_alpha_star,{k}_lo,{k}_hi,{k}_boot_std,{k}_note" for k in ("verdict", "f", "h"))]
    for t in table:
        cells = [t["factor"], f'"{t["level"]}"', " ".join(f"{a:g}" for a in t["alphas"]), str(t["seeds"]),
                 str(t["points"]), f"{t['point_time_s']:.0f}"]
        for k in ("verdict", "f", "h"):
            x, err, lo, hi, boot, note = t["m"][k]
            cells += ["" if v is None else f"{v:.6g}" for v in (x, lo, hi, boot)] + [f'"{note}"']
        lines.append(",".join(cells))
    write_text(OUT / "alpha_star_factors.csv", "\n".join(lines) + "\n")
    # Markdown
    md = ["# alpha* against each factor", "",
          "Generated by `python scripts/alpha_star_factors.py` from the sweeps' results.csv (g = 10 m/s^2, "
          "mu = 0.2, rod model by the sag rule, the exact contact law (Signorini and the Coulomb cone) with rolling "
          "rods unless the row says otherwise (IMC rows: DisMech's law, delta = d/10, k_c = 1000 rod weights per "
          "delta, spin locked); entangling 5 s at 10 Hz, 5 cm; test 5 s, that is 5.6 to 126 drive cycles). alpha* is "
          "the bracket of alphas between which the measure crosses 1/2 (stable seeds per alpha beside it); 'below X' / "
          "'above X' when every alpha is on one side. These tests are of unequal cycles and read at one instant: "
          "superseded by `scripts/alpha_star_controls.py` (50 cycles, landed measures; docs/transition.md). Point time: the sum of the points' own wall times (2-core AMD EPYC, one or two points at "
          "a time).", "",
          "| factor | level | alphas | seeds | stable seeds per alpha | alpha* verdict | alpha* f >= 0.5 (paper) | "
          "alpha* h >= 0.26 | point time (s) |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for t in table:
        st = ", ".join(f"{a:g}: {t['stable'][a]}/{t['n'][a]}" for a in t["alphas"])
        md.append(f"| {t['factor']} | {t['level']} | {' '.join(f'{a:g}' for a in t['alphas'])} | {t['seeds']} | "
                  f"{st} | {_fmt(t['m']['verdict'])} | {_fmt(t['m']['f'])} | {_fmt(t['m']['h'])} | "
                  f"{t['point_time_s']:.0f} |")
    if missing:
        md += ["", "Not measured yet: " + "; ".join(missing) + "."]
    md += ["", "References: " + "; ".join(f"{k} {v:g}" for k, v in REFERENCES.items()) + "."]
    write_text(OUT / "alpha_star_factors.md", "\n".join(md) + "\n")
    # figure: one row per level, alpha* by each measure with its bracket
    from matplotlib.lines import Line2D

    fig, ax = plt.subplots(figsize=(10, 0.75 * len(table) + 2.6))
    colours = {"verdict": "C0", "f": "C1", "h": "C2"}
    names = {"verdict": "verdict (h, f, persistence)", "f": "f >= 0.5 (the paper's measure)", "h": "h >= 0.26"}
    for i, t in enumerate(table):
        y = len(table) - 1 - i
        for j, k in enumerate(("verdict", "f", "h")):
            x, err, lo, hi, boot, note = t["m"][k]
            yy = y + (1 - j) * 0.22
            if x is not None:
                ax.plot([lo, hi], [yy, yy], "-", color=colours[k], lw=3)
            elif lo is not None:  # above the largest alpha measured
                ax.annotate("", xy=(lo * 1.7, yy), xytext=(lo, yy),
                            arrowprops=dict(arrowstyle="-|>", color=colours[k], lw=1.5))
            elif hi is not None:  # below the smallest
                ax.annotate("", xy=(hi / 1.7, yy), xytext=(hi, yy),
                            arrowprops=dict(arrowstyle="-|>", color=colours[k], lw=1.5))
    styles = dict(zip(REFERENCES, ("--", "-", ":")))
    for name, v in REFERENCES.items():
        ax.axvline(v, color="grey", ls=styles[name], lw=1)
    handles = [Line2D([], [], color=colours[k], lw=3, label=names[k]) for k in colours]
    handles += [Line2D([], [], color="grey", ls=styles[n], label=f"{n}: {v:g}") for n, v in REFERENCES.items()]
    ax.set_yticks(range(len(table)))
    ax.set_yticklabels([t["short"] for t in reversed(table)], fontsize=9)
    ax.set_ylim(-0.6, len(table) - 0.4)
    ax.set_xscale("log")
    ax.set_xlim(8, 400)
    ax.set_xlabel("alpha* = l / d [dimensionless]: the bracket between the last alpha that fails and the first "
                  "that holds; arrows: beyond the alphas run",
                  fontsize=9)
    ax.set_title("alpha* against each factor, 5 s tests (superseded by the 50-cycle controls): g = 10 m/s^2, 3 seeds",
                 fontsize=10)
    ax.legend(handles=handles, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
    fig.tight_layout()
    save_figure(fig, OUT / "alpha_star_factors.png")
    plt.close(fig)
    print((OUT / "alpha_star_factors.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
