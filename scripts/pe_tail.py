"""Is the upper tail of p(e) a power law? Clauset-Shalizi-Newman fits of the entanglement field.

For the authors' X-ray CT fields (every ``alpha{A}_epsilon{E}.npz`` in --data) and for the
simulated excitation packings given with --runs (the latest checkpoint's rods, through
``rodwarp analyze``), fit the tail of e over the valid voxels with
:func:`rodwarp.analysis.tail_fit` (xmin by KS, exponent by maximum likelihood, bootstrap
goodness of fit, Vuong tests against a lognormal and an exponential truncated at xmin).
When the ``powerlaw`` package (Alstott et al. 2014) is installed, it refits each tail at the
same xmin as a check (comparison only; rodwarp does not depend on it).

    python scripts/pe_tail.py --data PAPER_FIELDS_FOLDER [--runs RUN_DIR ...] [--boot 200]

Writes benchmarks/results/pe_tail.json and pe_tail.md.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
NAME = re.compile(r"alpha(\d+)_epsilon(\d+)\.npz$")
RUN = re.compile(r"alpha(\d+)")


def _provenance() -> dict:
    sys.path.insert(0, str(ROOT))
    from benchmarks.common import cpu_model, git_info, utc_now

    from rodwarp._util import versions

    try:
        import powerlaw
        pl = getattr(powerlaw, "__version__", None) or _dist_version("powerlaw")
    except ImportError:
        pl = None
    return {"date": utc_now(), "cpu": cpu_model(), "git": git_info(),
            "versions": {**versions(), "powerlaw": pl}}


def _dist_version(name: str) -> str | None:
    from importlib import metadata
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _rods_from_run(run: Path, out: Path) -> dict:
    """The latest checkpoint's vertices as a rod set (radii, units and box of initial.npz)."""
    from rodwarp.rodset import RodSet
    from rodwarp.rodset.trajectory import latest_checkpoint

    rs = RodSet.load(run / "initial.npz")
    got = latest_checkpoint(run / "checkpoints")
    if got is None:
        raise SystemExit(f"{run}: no readable checkpoint")
    arrays, _ = got
    x = arrays["state_x"]
    k = x.shape[0] // rs.n_rods
    if k * rs.n_rods != x.shape[0]:
        raise SystemExit(f"{run}: {x.shape[0]} vertices do not split over {rs.n_rods} rods")
    RodSet.from_polylines(list(x.reshape(rs.n_rods, k, 3)), rs.radii, units=rs.units, box=rs.box).save(out)
    return {"n_rods": int(rs.n_rods), "time_s": float(arrays["state_time"])}


def _analyze(rods: Path, out: Path) -> Path:
    exe = Path(sys.executable).with_name("rodwarp")
    cmd = [str(exe) if exe.exists() else "rodwarp", "analyze", str(rods), "--quiet", "--no-figures",
           "--out", str(out)]
    subprocess.run(cmd, check=True)
    return out / "fields.zarr"


def _powerlaw_check(e: np.ndarray, xmin: float) -> dict | None:
    """The same tail refitted by the powerlaw package at our xmin. Its default range for the
    exponent stops at 3 (powerlaw 2.0), which the CT tails exceed: it is widened to [1, 50]."""
    try:
        import powerlaw
    except ImportError:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f = powerlaw.Fit(e, xmin=xmin, verbose=False, parameter_ranges={"alpha": [1.0, 50.0]})
        d = powerlaw.Fit(e, xmin=xmin, verbose=False)
        out = {"alpha": float(f.power_law.alpha), "D": float(f.power_law.D),
               "alpha_default_range": float(d.power_law.alpha)}
        for alt in ("lognormal", "exponential"):
            r, p = f.distribution_compare("power_law", alt, normalized_ratio=True)
            out[alt] = {"R_norm": float(r), "p": float(p)}
    return out


def _row(label: str, kind: str, e: np.ndarray, boot: int, seed: int, extra: dict) -> dict:
    from rodwarp.analysis import power_law_fit, tail_fit

    e = e[np.isfinite(e)]
    t0 = time.perf_counter()
    fit = tail_fit(e, seed=seed, n_boot=boot)
    secs = time.perf_counter() - t0
    wide = power_law_fit(e)  # the widest-range fit that docs cited, for contrast
    pos = e[e > 0]
    return {"label": label, "kind": kind, **extra, "n_valid": int(e.size), "n_positive": int(pos.size),
            "e_median": float(np.median(pos)), "e_p95": float(np.percentile(pos, 95)),
            "fit": fit.as_dict(), "fit_seconds": round(secs, 2),
            "powerlaw_pkg": _powerlaw_check(pos.astype(np.float64), fit.xmin),
            "widest_range_fit": None if wide is None else
            {k: wide[k] for k in ("gamma", "xmin", "xmax", "decades", "n_range", "accepted")}}


def _fmt_p(p: float, n_boot: int | None = None) -> str:
    if not np.isfinite(p):
        return "-"
    if n_boot and p == 0.0:  # no bootstrap sample as far off: p is below the resolution 1 / n_boot
        return f"< {1.0 / n_boot:.2g}"
    return "< 1e-15" if p < 1e-15 else (f"{p:.2g}" if p < 0.01 else f"{p:.2f}")


def _markdown(rec: dict) -> str:
    prov = rec["provenance"]
    v = prov["versions"]
    lines = [
        "# The upper tail of p(e): power law or not?",
        "",
        f"Generated by `{rec['command']}` on {prov['date']} ({prov['cpu']}; rodwarp {v['rodwarp']}, git "
        f"{prov['git']['commit']}, numpy {v['numpy']}, scipy {v['scipy']}, powerlaw {v['powerlaw']}).",
        "",
        "Method: `rodwarp.analysis.tail_fit` (Clauset, Shalizi & Newman 2009) on the valid voxels with e > 0: "
        "p(e) ~ e^-a for e >= xmin, a by maximum likelihood, xmin minimising the KS distance over 100 "
        "candidates (tail of at least 50 values and 5 % of the sample: xmin <= the 95th percentile), "
        f"se = (a - 1) / sqrt(n_tail); gof p from {rec['settings']['n_boot']} semi-parametric bootstrap samples "
        f"(seed {rec['settings']['seed']}); R_norm and p: Vuong's normalised log-likelihood ratio of the power law "
        "against a lognormal (LN) and an exponential (EXP) fitted by maximum likelihood to the same tail "
        "(R_norm > 0 favours the power law, < 0 the alternative). Voxels are overlapping balls, not independent "
        "samples: se is too small and the p-values too extreme, so read the signs and the orders of magnitude. "
        "'limit': xmin sits at the highest candidate allowed (the KS distance was still falling).",
        "",
        "| data | n | xmin | e_p95 | a +- se | n_tail | decades | KS D | gof p | R_norm LN (p) | "
        "R_norm EXP (p) | verdict |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rec["rows"]:
        f = r["fit"]
        lim = " (limit)" if f["xmin_at_limit"] else ""
        lines.append(
            f"| {r['label']} | {f['n']} | {f['xmin']:.3g}{lim} | {r['e_p95']:.3g} | {f['alpha']:.2f} +- "
            f"{f['alpha_se']:.2f} | {f['n_tail']} | {f['decades']:.2f} | {f['ks']:.3f} | {_fmt_p(f['gof_p'], f['n_boot'])} | "
            f"{f['lognormal']['R_norm']:+.1f} ({_fmt_p(f['lognormal']['p'])}) | "
            f"{f['exponential']['R_norm']:+.1f} ({_fmt_p(f['exponential']['p'])}) | {f['verdict']} |")
    lines += ["", "## The widest-range fit (`power_law_fit`) on the same data, for contrast", "",
              "The range the earlier statement rested on: where it lies against the tail above.", "",
              "| data | gamma | range | decades | values in range |", "|---|---:|---|---:|---:|"]
    for r in rec["rows"]:
        w = r["widest_range_fit"]
        if w:
            lines.append(f"| {r['label']} | {w['gamma']:.2f} | {w['xmin']:.2g} - {w['xmax']:.2g} | "
                         f"{w['decades']:.1f} | {w['n_range']} |")
    pk = [r for r in rec["rows"] if r["powerlaw_pkg"]]
    lines += ["", "## Check against the powerlaw package (Alstott, Bullmore & Plenz 2014)", ""]
    if not pk:
        lines.append("powerlaw is not installed here; no check was run.")
    else:
        da = max(abs(r["powerlaw_pkg"]["alpha"] - r["fit"]["alpha"]) for r in pk)
        dr = max(abs(r["powerlaw_pkg"][k]["R_norm"] - r["fit"][k]["R_norm"]) for r in pk
                 for k in ("lognormal", "exponential"))
        capped = sum(1 for r in pk if r["powerlaw_pkg"]["alpha_default_range"] < r["fit"]["alpha"] - 0.01)
        lines += [
            f"Refitted at the same xmin with powerlaw {v['powerlaw']} (exponent range widened to [1, 50]): largest "
            f"difference in a: {da:.2g}; in R_norm (LN and EXP): {dr:.2g}, over {len(pk)} data sets. "
            f"With its default exponent range powerlaw returns a = 3.00 for {capped} of them (its range stops at "
            "3, silently), so its defaults would misreport these tails. Its own xmin search scans every distinct "
            "value (about 4 minutes per CT field on this machine) and was not run here; on synthetic samples it "
            "lands within a few per cent of tail_fit's xmin. rodwarp keeps its own implementation (NumPy/SciPy, "
            "seeded, no extra dependency); powerlaw served only as this check."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="folder of the authors' alpha*_epsilon*.npz fields")
    ap.add_argument("--runs", nargs="*", default=[], help="excitation run folders (initial.npz, checkpoints/)")
    ap.add_argument("--boot", type=int, default=200, help="bootstrap samples per data set")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    a = ap.parse_args(argv)

    import json

    from rodwarp._util import json_safe
    from rodwarp.analysis import Fields

    rows = []
    files = sorted((p for p in Path(a.data).glob("*.npz") if NAME.search(p.name)),
                   key=lambda p: tuple(int(g) for g in NAME.search(p.name).groups()))
    for p in files:
        alpha, eps = (int(g) for g in NAME.search(p.name).groups())
        f = Fields.load(p)
        rows.append(_row(f"CT alpha {alpha}, eps {eps / 100:.2f}", "ct", f.e[f.valid].astype(np.float64),
                         a.boot, a.seed, {"file": p.name, "alpha": alpha, "epsilon": eps / 100}))
        print(rows[-1]["label"], rows[-1]["fit"]["verdict"], flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for run in map(Path, a.runs):
            m = RUN.search(run.name)
            rods = Path(tmp) / f"{run.name}.npz"
            info = _rods_from_run(run, rods)
            f = Fields.load(_analyze(rods, Path(tmp) / run.name))
            rows.append(_row(f"sim {run.name} (t = {info['time_s']:.0f} s)", "sim", f.e[f.valid].astype(np.float64),
                             a.boot, a.seed, {"run": run.name, "alpha": int(m.group(1)) if m else None, **info}))
            print(rows[-1]["label"], rows[-1]["fit"]["verdict"], flush=True)

    cmd = "python scripts/pe_tail.py --data PAPER_FIELDS " + " ".join(
        ["--runs", *[Path(r).as_posix() for r in a.runs]] if a.runs else []) + f" --boot {a.boot} --seed {a.seed}"
    rec = {"command": cmd.strip(), "provenance": _provenance(),
           "settings": {"n_boot": a.boot, "seed": a.seed, "min_tail": 50, "max_quantile": 0.95, "candidates": 100,
                        "values": "valid voxels with e > 0"},
           "rows": rows}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "pe_tail.json").write_text(json.dumps(json_safe(rec), indent=1) + "\n")
    (out / "pe_tail.md").write_text(_markdown(rec))
    print(f"wrote {out / 'pe_tail.md'} and pe_tail.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
