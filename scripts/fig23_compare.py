"""The paper's Fig. 2 and 3 on simulated poured packings beside the authors' CT fields.

For each aspect ratio of the CT data (alpha 38, 66, 76, 100), the simulated packing is the
excitation experiment's pour (the paper's rods and N = 1.25e6 / (d l^2), poured into a 60 mm
tube inside the 150 mm container, the tube removed and the packing let stand: the frame at
the end of its ``release`` stage, before any shaking; docs/experiments.md). Its fields are
computed by ``rodwarp analyze`` (R = sqrt(d l), spacing R / 2, the convention given); the CT
packing's are the published ones at strain 0, run through the same statistics.

Figures (benchmarks/results/): ``fig2_pS_pc.png`` (p(S) and p(c), Fig. 2), ``fig3_tangles.png``
(tangles, the largest tangle's extent and percolation against alpha, Fig. 3F-I) and
``fig3_zprofiles.png`` (phi(z), S(z), c(z), e(z) against z / l, the change near z ~ l / 2 of
Fig. 3J-M and S14); the numbers in ``fig23.md`` and ``fig23.json``.

    python scripts/fig23_compare.py --paper-fields DIR [--runs runs/excitation] [--work runs/fig23]
                                    [--convention authors|text] [--edge 2]

The simulated packings come from ``python scripts/excitation_experiments.py run`` (their run
folders, ``main_alpha{A}_seed0``); an alpha without its run is left out and said so.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

ALPHAS = (38, 66, 76, 100)
#: rod length (m) of each alpha's rods in the paper's experiments (docs/experiments.md)
LENGTH = {38: 0.025, 66: 0.05, 76: 0.05, 100: 0.05}
#: the CT's voxel edge (m): about 78 um (docs/experiments.md)
CT_VOXEL = 78e-6
FIELDS = ("phi", "S", "c", "e")


def released_packing(run: Path):
    """The rod set at the end of the run's ``release`` stage (the poured packing standing
    after the tube is removed), and that time (s)."""
    import zarr

    from rodwarp.rodset import RodSet

    with open(run / "metrics.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["stage"] == "release"]
    if not rows:
        raise RuntimeError(f"{run}: no release stage in metrics.csv")
    t_end = float(rows[-1]["time"])
    g = zarr.open_group(str(run / "trajectory.zarr"), mode="r")
    times = np.asarray(g["time"][:])
    k = int(np.nanargmin(np.abs(times - t_end)))
    pos = np.asarray(g["positions"][k])
    off = np.asarray(g.attrs["offsets"], dtype=np.int64)
    radii = np.asarray(g.attrs["radii"], dtype=np.float64)
    polys = [pos[off[i]:off[i + 1]] for i in range(len(off) - 1)]
    return RodSet.from_polylines(polys, radii=radii, units="m"), float(times[k])


def resampled(rods, edge_diameters: float):
    """``rods`` with every polyline resampled to edges of about ``edge_diameters`` rod diameters.

    The authors' rules keep whole edges by their first vertex, so their fields depend on the
    edge length (docs/fields.md, "The authors' convention"); rigid rods are stored as one edge
    each, which no ball of radius sqrt(d l) would keep. The CT centrelines' edge length is not
    published: the comparison states the one used."""
    from rodwarp.rodset import RodSet

    polys = []
    for i in range(rods.n_rods):
        pts = rods.points[rods.offsets[i]:rods.offsets[i + 1]]
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        n = max(2, int(round(s[-1] / (edge_diameters * 2 * rods.radii[i]))) + 1)
        t = np.linspace(0.0, s[-1], n)
        polys.append(np.stack([np.interp(t, s, pts[:, k]) for k in range(3)], axis=1))
    return RodSet.from_polylines(polys, radii=rods.radii, units=rods.units)


def analysed(src: Path, out: Path, convention: str) -> tuple[dict, object]:
    """``rodwarp analyze`` of ``src`` into ``out`` (kept when done before): summary and fields."""
    from rodwarp.analysis import AnalyzeOptions, Fields, analyze

    if not (out / "summary.json").is_file():
        kw = {"figures": False, "device": "cpu"}
        if convention != "text":
            kw["convention"] = convention
        analyze(src, out, AnalyzeOptions(**kw), progress=False, overwrite=True)
    return json.loads((out / "summary.json").read_text()), Fields.load(out / "fields.zarr")


def field_values(fields, name: str) -> np.ndarray:
    """The valid voxels' finite values of the field ``name`` (``phi``, ``S``, ``c``, ``e``)."""
    v = np.asarray(getattr(fields, name), dtype=float)
    return v[fields.valid & np.isfinite(v)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", default=str(ROOT / "runs" / "excitation"))
    ap.add_argument("--work", default=str(ROOT / "runs" / "fig23"))
    ap.add_argument("--paper-fields", required=True, help="folder of the authors' alpha*_epsilon*.npz fields")
    ap.add_argument("--convention", default="authors", help="the fields' convention for the simulated packings "
                    "(authors: the published CT fields' own, like for like; text: the paper's definitions)")
    ap.add_argument("--edge", type=float, default=2.0, help="edge length (rod diameters) the simulated rods are "
                    "resampled to for the authors' convention (the CT centrelines' is not published)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = ap.parse_args(argv)
    runs, work, out = Path(args.runs), Path(args.work), Path(args.out)
    work.mkdir(parents=True, exist_ok=True)
    data, missing = {}, []
    for a in ALPHAS:
        run = runs / f"main_alpha{a}_seed0"
        ct = Path(args.paper_fields) / f"alpha{a}_epsilon00.npz"
        if not (run / "trajectory.zarr").exists() or not ct.is_file():
            missing.append(a)
            continue
        t0 = time.perf_counter()
        rods, t_rel = released_packing(run)
        src = work / f"alpha{a}_released.npz"
        if not src.is_file():
            rods.save(src)
        if args.convention == "authors":
            src = work / f"alpha{a}_released_edge{args.edge:g}d.npz"
            if not src.is_file():
                resampled(rods, args.edge).save(src)
        tag = args.convention + (f"_edge{args.edge:g}d" if args.convention == "authors" else "")
        sim_s, sim_f = analysed(src, work / f"alpha{a}_sim_{tag}", args.convention)
        ct_s, ct_f = analysed(ct, work / f"alpha{a}_ct", "text")
        data[a] = {"sim": (sim_s, sim_f), "ct": (ct_s, ct_f), "t_release": t_rel, "n_rods": rods.n_rods,
                   "wall_s": time.perf_counter() - t0}
        print(f"alpha {a}: {rods.n_rods} rods at t = {t_rel:.3f} s; analysed in {data[a]['wall_s']:.0f} s",
              flush=True)
    if not data:
        print("no alpha has both a simulated run and CT fields", file=sys.stderr)
        return 1
    write_figures(data, out, args.convention)
    write_tables(data, out, args, missing)
    return 0


def _z_over_l(summary: dict, a: int, ct: bool) -> np.ndarray:
    z = np.asarray(summary["z_profiles"]["z"], dtype=float)
    z = z - np.nanmin(z) + float(summary["radius"])  # the lowest ball centre lies R above the floor
    return z * (CT_VOXEL if ct else 1.0) / LENGTH[a]


def _profile(summary: dict, name: str) -> np.ndarray:
    prof = summary["z_profiles"]
    v = prof.get(name, prof.get(name.lower()))
    return np.asarray([np.nan if x is None else x for x in v], dtype=float)


def write_figures(data: dict, out: Path, convention: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = dict(zip(ALPHAS, ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    # Fig. 2: p(S) and p(c)
    fig, axes = plt.subplots(2, 2, figsize=(9, 6.5))
    for col, name in enumerate(("S", "c")):
        for row, src in enumerate(("ct", "sim")):
            ax = axes[row, col]
            for a, d in data.items():
                v = field_values(d[src][1], name)
                if v.size:
                    ax.hist(v, bins=40, density=True, histtype="step", color=colours[a], label=f"alpha {a}")
            ax.set_title(f"p({name}), {'CT (authors, strain 0)' if src == 'ct' else 'simulated pour (' + convention + ')'}",
                         fontsize=9)
            ax.set_xlabel(name)
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig2_pS_pc.png", dpi=130)
    plt.close(fig)
    # Fig. 3F-I: tangles against alpha
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.4))
    for src, marker in (("ct", "o"), ("sim", "s")):
        al = sorted(data)
        n_t = [data[a][src][0].get("n_tangles") or 0 for a in al]
        ext = [max((data[a][src][0].get("largest_tangle_extent") or {}).get(k) or 0 for k in "xyz") for a in al]
        perc = [1.0 if data[a][src][0].get("percolates") else 0.0 for a in al]
        lab = "CT" if src == "ct" else "simulated pour"
        axes[0].plot(al, n_t, marker, ls="-", label=lab)
        axes[1].plot(al, ext, marker, ls="-", label=lab)
        axes[2].plot(al, perc, marker, ls="-", label=lab)
    for ax, t in zip(axes, ("tangles", "largest tangle: max xi / L", "percolates (1 yes)")):
        ax.set_xlabel("alpha")
        ax.set_title(t, fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig3_tangles.png", dpi=130)
    plt.close(fig)
    # Fig. 3J-M: z-profiles, one panel per field, CT solid and simulation dashed
    fig, axes = plt.subplots(1, 4, figsize=(13, 3.6))
    for ax, name in zip(axes, FIELDS):
        for a, d in data.items():
            for src, ls in (("ct", "-"), ("sim", "--")):
                s = d[src][0]
                ax.plot(_z_over_l(s, a, src == "ct"), _profile(s, name), ls, color=colours[a],
                        label=f"alpha {a} {'CT' if src == 'ct' else 'sim'}")
        ax.axvline(0.5, color="grey", lw=0.8)
        ax.set_xlabel("z / l")
        ax.set_title(f"{name}(z)", fontsize=9)
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(out / "fig3_zprofiles.png", dpi=130)
    plt.close(fig)


def _median(fields, name):
    v = field_values(fields, name)
    return float(np.median(v)) if v.size else None


def write_tables(data: dict, out: Path, args, missing: list) -> None:
    sys.path.insert(0, str(ROOT))
    from benchmarks.common import cpu_model

    from rodwarp._util import version_line

    rows, table = {}, []
    for a, d in sorted(data.items()):
        rows[a] = {}
        for src in ("ct", "sim"):
            s, f = d[src]
            rows[a][src] = {"median_S": _median(f, "S"), "median_c": _median(f, "c"), "mean_e": s.get("mean_e"),
                            "cv_e": s.get("cv_e"), "n_tangles": s.get("n_tangles"),
                            "largest_tangle_extent": s.get("largest_tangle_extent"),
                            "percolates": s.get("percolates")}
            r = rows[a][src]
            ext = r["largest_tangle_extent"] or {}
            table.append(f"| {a} | {'CT, strain 0' if src == 'ct' else 'simulated pour'} | "
                         f"{_g(r['median_S'])} | {_g(r['median_c'])} | {_g(r['mean_e'])} | {_g(r['cv_e'])} | "
                         f"{r['n_tangles']} | {', '.join(_g(ext.get(k)) for k in 'xyz')} | {r['percolates']} |")
    meta = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "versions": version_line(),
            "cpu": cpu_model(), "command": "python scripts/fig23_compare.py " + " ".join(
                Path(a).name if i and sys.argv[i - 1] == "--paper-fields" else a for i, a in enumerate(sys.argv)
                if i),
            "convention_sim": args.convention, "missing_alphas": missing,
            "packings": {a: {"n_rods": d["n_rods"], "t_release_s": d["t_release"]} for a, d in data.items()},
            "rows": rows}
    (out / "fig23.json").write_text(json.dumps(meta, indent=1, default=str))
    lines = ["# Fig. 2-3 on simulated poured packings beside the CT", "",
             f"Generated by `{meta['command']}` on {meta['date']} ({meta['versions']}; {meta['cpu']}).",
             "Simulated: the excitation experiment's pour (the paper's rods and N, exact contact law, mu 0.2, "
             "seed 0) at the end of its release stage, before shaking; fields by `rodwarp analyze` "
             f"(convention {args.convention}" + (f", rods resampled to edges of {args.edge:g} d" if args.convention
                                                 == "authors" else "") + ", R = sqrt(d l), spacing R/2, the "
             "packing's bounding box). CT: the authors' published fields at strain 0 (their convention), "
             "through the same statistics. The authors' phi needs the CT image, so the simulated phi is NaN "
             "under their convention; their c normalises by the whole packing's bounding cylinder.",
             "" if not missing else f"Left out (no run or no CT fields): alpha {', '.join(map(str, missing))}.", "",
             "| alpha | packing | median S | median c | mean e | cv_e | tangles | largest tangle xi/L (x, y, z) "
             "| percolates |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |", *table, "",
             "Figures: [fig2_pS_pc.png](fig2_pS_pc.png), [fig3_tangles.png](fig3_tangles.png), "
             "[fig3_zprofiles.png](fig3_zprofiles.png)."]
    (out / "fig23.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'fig23.md'}")


def _g(v) -> str:
    return "n/a" if v is None else (f"{v:.3g}" if isinstance(v, float) else str(v))


if __name__ == "__main__":
    sys.exit(main())
