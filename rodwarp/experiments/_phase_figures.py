"""The figures of the entanglement phase diagram, drawn by :func:`~rodwarp.experiments.phase_diagram`.

From a sweep's ``ok`` rows (read in :mod:`rodwarp.experiments._phase`): Fig. 4L (cv_e against
a/g, coloured by the verdict), Fig. 4H (f against alpha), Fig. 4I (f against a/g), the
verdict's measures against alpha, alpha* against a/g (and against the static load); from each
point's own files: Fig. 4C-D (Z(t), f(t), cv_e(t) from its metrics.csv) and Fig. 4E-F (p(e),
p(c) and their fitted power laws from its analysis/fields.zarr). Matplotlib is imported inside
each figure function.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

from rodwarp.errors import RodwarpError
from rodwarp.experiments.protocols.paper import ENTANGLE, TEST
from rodwarp.rodset.files import save_figure

#: colours of stable and unstable points
BLUE, RED = "#1f5fbf", "#c62828"
#: resolution of the phase-diagram PNGs (dots per inch)
DPI = 120


def _num(s):
    """A finite float of a CSV cell, None when empty, unparsable or not finite (lenient: for
    files other than results.csv)."""
    if s is None or s == "":
        return None
    try:
        v = float(s)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _point_file(out: Path, r: dict, *parts) -> Path | None:
    """A file of point ``r``'s folder (``out/points/<id>/...``), None when it is missing."""
    if not r.get("id"):
        return None
    p = Path(out, "points", r["id"], *parts)
    return p if p.exists() else None


def _title(key) -> str:
    ag, g, s = key
    return f"a/g = {ag:g}, g = {g:g} m/s^2, F~ = {s:g}"


#: columns of a point's metrics.csv that the time-series figure draws
_SERIES = ("contacts_per_rod", "largest_cluster_fraction", "cv_e")


def _metrics(path: Path) -> list[dict]:
    """The rows of a point's ``metrics.csv`` for :func:`_timeseries_figure`: ``time`` a float,
    ``stage`` a string, the drawn columns floats or "" (not sampled).

    Raises
    ------
    RodwarpError
        One line naming the file (and the row and column) when it is not a UTF-8 CSV, lacks
        ``time`` or ``stage``, or holds a value that is not a finite number.
    """
    from rodwarp.rodset.files import read_csv_rows

    fix = "it is the point's own record: restore it, or delete it to leave the point out of the time series"
    header, raw = read_csv_rows(path, fix)
    missing = [c for c in ("time", "stage") if c not in header]
    if missing:
        raise RodwarpError(f"{path} lacks the column(s) {', '.join(missing)}; {fix}")
    rows = []
    for i, x in enumerate(raw, 1):
        d = {"stage": x.get("stage") or ""}
        for col in ("time", *_SERIES):
            cell = x.get(col)
            if col != "time" and (cell is None or cell.strip() == ""):
                d[col] = ""
                continue
            v = _num(cell)
            if v is None:
                raise RodwarpError(f"{path} row {i}: {col} = {cell!r} is not a finite number; {fix}")
            d[col] = v
        rows.append(d)
    return rows


def _timeseries_figure(out: Path, key, rows, path: Path) -> Path | None:
    """Fig. 4C-D: Z(t), f(t) and cv_e(t) through entangling and the test, one colour per alpha
    (each seed a line), the test's start dashed."""
    import matplotlib.pyplot as plt

    series = []
    for r in rows:
        f = _point_file(out, r, "metrics.csv")
        if f is not None:
            series.append((r["alpha"], _metrics(f)))
    if not series:
        return None
    alphas = sorted({a for a, _ in series})
    cmap = plt.get_cmap("viridis")
    fig, axs = plt.subplots(1, 3, figsize=(13, 3.8))
    has_cv = False
    t_test = None
    labelled = set()
    for a, m in series:
        colour = cmap(alphas.index(a) / max(len(alphas) - 1, 1))
        t = [float(x["time"]) for x in m]
        for ax, col in zip(axs, ("contacts_per_rod", "largest_cluster_fraction", "cv_e")):
            pts = [(ti, float(x[col])) for ti, x in zip(t, m) if x.get(col, "") not in ("", None)]
            if col == "cv_e":
                has_cv = has_cv or bool(pts)
            if pts:
                label = f"alpha = {a:g}" if ax is axs[0] and a not in labelled else None
                if label:
                    labelled.add(a)
                ax.plot(*zip(*pts), color=colour, lw=1, marker="o" if col == "cv_e" else None, ms=2, label=label)
        # the test starts where entangling ends (its last sample, the run's test_start), not
        # at the first stability sample one save interval later
        ent = [float(x["time"]) for x in m if x["stage"] == ENTANGLE]
        if ent and any(x["stage"] == TEST for x in m):
            t_test = max(ent)
    for ax, label in zip(axs, ("Z (contacts per rod)", "f (largest cluster)", "cv_e = sigma_e / mu_e")):
        ax.set_xlabel("t (s)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if t_test is not None:
            ax.axvline(t_test, ls="--", lw=0.8, color="0.5")
    if not has_cv:
        axs[2].text(0.5, 0.5, "no cv_e(t) in these runs\n(--fields-every 0 or older runs)", ha="center",
                    transform=axs[2].transAxes, fontsize=8)
    axs[0].legend(fontsize=7)
    fig.suptitle(f"entanglement over time ({_title(key)}; dashed: the test starts)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=DPI)
    plt.close(fig)
    return path


def _distributions_figure(out: Path, key, rows, path: Path):
    """Fig. 4E-F: p(e) and p(c) per alpha (valid voxels pooled over seeds, log bins) with the
    fitted power laws over their ranges; returns the path (None without fields) and one table row per
    alpha and field."""
    import matplotlib.pyplot as plt
    import numpy as np

    from rodwarp.analysis import Fields, log_histogram, power_law_density, power_law_fit

    pooled: dict = {}
    for r in rows:
        f = _point_file(out, r, "analysis", "fields.zarr")
        if f is None:
            continue
        fl = Fields.load(f)
        for name in ("e", "c"):
            a = fl.get(name)
            pooled.setdefault(r["alpha"], {}).setdefault(name, []).append(a[fl.valid & np.isfinite(a)])
    if not pooled:
        return None, []
    alphas = sorted(pooled)
    cmap = plt.get_cmap("viridis")
    fig, axs = plt.subplots(1, 2, figsize=(10, 4))
    table = []
    for a in alphas:
        colour = cmap(alphas.index(a) / max(len(alphas) - 1, 1))
        for ax, name in zip(axs, ("e", "c")):
            v = np.concatenate(pooled[a][name])
            v = v[v > 0]
            fit = power_law_fit(v)
            table.append({"a_over_g": key[0], "gravity": key[1], "static_load": key[2], "alpha": a, "field": name,
                          "seeds": len(pooled[a][name]), "voxels": int(v.size),
                          **({k: fit[k] for k in ("gamma", "gamma_err", "xmin", "xmax", "decades", "n_range", "ks",
                                                  "accepted", "note")} if fit else {"note": "too few values"})})
            h = log_histogram(v)
            if h is None:
                continue
            label = f"alpha = {a:g}"
            if fit:
                label += f": gamma = {fit['gamma']:.2f} ({fit['decades']:.1f} dec.)"
                x = np.geomspace(fit["xmin"], fit["xmax"], 20)
                ax.loglog(x, power_law_density(x, fit), "-", color=colour, lw=1.5, alpha=0.6)
            ax.loglog(h["x"], h["density"], "o", ms=3, color=colour, label=label)
    for ax, name in zip(axs, ("e (ACN per ball)", "c (contacts per ball)")):
        ax.set_xlabel(name)
        ax.set_ylabel("density")
        ax.grid(alpha=0.3, which="major")
        ax.legend(fontsize=6)
    fig.suptitle(f"p(e) and p(c) ({_title(key)}; lines: fitted power laws over their ranges)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=DPI)
    plt.close(fig)
    return path, table


def _finish(fig, ax, path: Path, *, xlabel: str, ylabel: str, title: str, legend: int | None = 7, ncol: int = 1,
            ylim=None, title_size: int = 9) -> Path:
    """Label one phase-diagram axis (log x), save the figure as ``path`` and close it."""
    import matplotlib.pyplot as plt

    ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if ylim is not None:
        ax.set_ylim(*ylim)
    ax.set_title(title, fontsize=title_size)
    if legend:
        ax.legend(fontsize=legend, ncol=ncol)
    fig.tight_layout()
    save_figure(fig, path, dpi=DPI)
    plt.close(fig)
    return path


def _mean_by(rs, key, value="largest_cluster_fraction"):
    """Sorted values of ``key``, the mean of ``value`` at each, and half its range (seed spread)."""
    d: dict = {}
    for r in rs:
        if r[value] is not None:
            d.setdefault(r[key], []).append(r[value])
    ks = sorted(d)
    return ks, [sum(d[k]) / len(d[k]) for k in ks], [(max(d[k]) - min(d[k])) / 2 for k in ks]


def _cv_e_figure(rows, path: Path) -> Path:
    """Fig. 4L: cv_e against a/g, coloured by the verdict, the best separating level shaded."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    cv = [r for r in rows if r["cv_e"] is not None]
    if cv:
        st = [r["cv_e"] for r in cv if r["stable"]]
        un = [r["cv_e"] for r in cv if not r["stable"]]
        ymax = max(r["cv_e"] for r in cv) * 1.15 + 1e-9
        ymin = min(0.0, min(r["cv_e"] for r in cv))
        # one horizontal boundary that best separates the classes; shaded on each side
        if st and un:
            cands = sorted({r["cv_e"] for r in cv})
            cuts = [0.5 * (a + b) for a, b in zip(cands, cands[1:])] or cands
            hi_stable = (sum(st) / len(st)) >= (sum(un) / len(un))

            def acc(c):
                return sum((r["cv_e"] >= c) == (r["stable"] == hi_stable) for r in cv)

            cut = max(cuts, key=acc)
            top, bottom = (BLUE, RED) if hi_stable else (RED, BLUE)
            ax.axhspan(cut, ymax, color=top, alpha=0.12, lw=0)
            ax.axhspan(ymin, cut, color=bottom, alpha=0.12, lw=0)
            ax.axhline(cut, color="0.4", ls=":", lw=0.8)
        else:
            ax.axhspan(ymin, ymax, color=BLUE if st else RED, alpha=0.12, lw=0)
        for flag, col, lab in ((True, BLUE, "stable"), (False, RED, "unstable")):
            sel = [r for r in cv if r["stable"] == flag]
            if sel:
                ax.scatter([r["a_over_g"] for r in sel], [r["cv_e"] for r in sel], c=col, label=lab, s=28,
                           edgecolors="k", linewidths=0.4, zorder=3)
        ax.set_ylim(ymin, ymax)
    return _finish(fig, ax, path, xlabel="a/g", ylabel="sigma_e / mu_e", legend=8 if cv else None,
                   title="entanglement phase diagram (cf. Fig. 4L)")


def _f_alpha_figure(rows, path: Path) -> Path:
    """Fig. 4H: f against alpha for each a/g (and static load when several)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    loads = sorted({r["static_load"] for r in rows})
    for s in loads:
        for ag in sorted({r["ag"] for r in rows}):
            sel = [r for r in rows if r["ag"] == ag and r["static_load"] == s]
            if not sel:
                continue
            xs, ys, es = _mean_by(sel, "alpha")
            lab = f"a/g = {ag:.3g}" + (f", F~ = {s:g}" if len(loads) > 1 else "")
            ax.errorbar(xs, ys, yerr=es if any(es) else None, fmt="o-", ms=4, capsize=2, label=lab)
    ax.axhline(0.5, ls=":", color="0.5", lw=0.8)
    return _finish(fig, ax, path, xlabel="aspect ratio alpha", ylabel="largest contact cluster fraction f",
                   ylim=(0, 1.05), title="f against alpha (cf. Fig. 4H)")


def _verdict_figure(rows, path: Path) -> Path:
    """The verdict's measures against alpha: height kept and persistence, with their thresholds."""
    import matplotlib.pyplot as plt

    from rodwarp.experiments._verdict import DEFAULT_THRESHOLDS as thr

    loads = sorted({r["static_load"] for r in rows})
    ags = sorted({r["ag"] for r in rows})
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, value, label, level in ((axes[0], "height_kept", "height kept h at the end", thr.height_kept),
                                    (axes[1], "persistence", "persistence tau", thr.persistence)):
        for j, s in enumerate(loads):
            for k, ag in enumerate(ags):
                sel = [r for r in rows if r["ag"] == ag and r["static_load"] == s and r[value] is not None]
                if not sel:
                    continue
                col = f"C{(j * len(ags) + k) % 10}"
                xs, ys, _ = _mean_by(sel, "alpha", value)
                ax.plot(xs, ys, "-", color=col, lw=1,
                        label=f"a/g = {ag:.3g}" + (f", F~ = {s:g}" if len(loads) > 1 else ""))
                for flag, face in ((True, col), (False, "white")):
                    pts_ = [r for r in sel if r["stable"] == flag]
                    ax.scatter([r["alpha"] for r in pts_], [r[value] for r in pts_], s=26, facecolors=face,
                               edgecolors=col, zorder=3)
        ax.axhline(level, ls=":", color="tab:red", lw=1, label=f"threshold {level:g}")
        ax.set_xscale("log")
        ax.set_xlabel("aspect ratio alpha")
        ax.set_ylabel(label)
        ax.set_ylim(0, 1.05)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("stability verdict against alpha (height kept, persistence)", fontsize=9)
    return _finish(fig, axes[1], path, xlabel="aspect ratio alpha", ylabel="persistence tau", ylim=(0, 1.05),
                   legend=None, title="filled: stable, open: unstable", title_size=8)


def _f_ag_figure(rows, path: Path) -> Path:
    """Fig. 4I: f against a/g for each alpha and static load."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    markers = "osD^v<>ph*"
    for j, s in enumerate(sorted({r["static_load"] for r in rows})):
        for a in sorted({r["alpha"] for r in rows}):
            sel = [r for r in rows if r["alpha"] == a and r["static_load"] == s]
            if not sel:
                continue
            xs, ys, es = _mean_by(sel, "ag")
            ax.errorbar(xs, ys, yerr=es if any(es) else None, fmt=markers[j % len(markers)] + "-", ms=4,
                        capsize=2, label=f"alpha = {a:g}, F~ = {s:g}")
    ax.axhline(0.5, ls=":", color="0.5", lw=0.8)
    return _finish(fig, ax, path, xlabel="a/g", ylabel="largest contact cluster fraction f", ylim=(0, 1.05),
                   legend=6, ncol=2, title="f against a/g (cf. Fig. 4I)")


def _alpha_star_figure(rows, table: list[dict], path: Path) -> Path:
    """alpha* against a/g with its uncertainty, and where it lies outside the alphas swept."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    amin = min(r["alpha"] for r in rows)
    amax = max(r["alpha"] for r in rows)
    gravities = sorted({t["gravity"] for t in table})
    styles = ("o-", "s--", "^:", "D-.")
    loads = sorted({r["static_load"] for r in rows})
    # one line per static load and gravity: a/g alone does not make two gravities one curve
    for (j, s), (m, g) in itertools.product(enumerate(loads), enumerate(gravities)):
        sel = sorted((t for t in table if t["static_load"] == s and t["gravity"] == g), key=lambda t: t["a_over_g"])
        if not sel:
            continue
        col = f"C{j}"
        lab = f"F~ = {s:g}" + (f", g = {g:g}" if len(gravities) > 1 else "")
        pts_ = [t for t in sel if t["alpha_star"] is not None]
        if pts_:
            yerr = [max(t["err"] or 0, t["boot_std"] or 0) for t in pts_]
            ax.errorbar([t["a_over_g"] for t in pts_], [t["alpha_star"] for t in pts_], yerr=yerr,
                        fmt=styles[m % len(styles)], color=col, capsize=3, label=lab)
            lab = None
        below = [t for t in sel if t["alpha_star"] is None and t["bracket_hi"] is not None]
        above = [t for t in sel if t["alpha_star"] is None and t["bracket_lo"] is not None]
        if below:
            ax.scatter([t["a_over_g"] for t in below], [t["bracket_hi"] for t in below], marker="v", color=col,
                       label=(lab + ": " if lab else "") + "alpha* below the smallest alpha")
        if above:
            ax.scatter([t["a_over_g"] for t in above], [t["bracket_lo"] for t in above], marker="^", color=col,
                       label=(lab + ": " if lab else "") + "alpha* above the largest alpha")
    ax.axhline(100, ls="--", color="0.5", lw=0.8, label="paper: alpha* ~ 100 at a/g ~ 1")
    ax.axvline(1, ls=":", color="0.7", lw=0.8)
    ax.set_yscale("log")
    return _finish(fig, ax, path, xlabel="a/g", ylabel="critical aspect ratio alpha* (half the seeds stable)",
                   ylim=(amin / 1.5, amax * 1.5), title="critical aspect ratio")


def _alpha_star_load_figure(rows, table: list[dict], path: Path) -> Path:
    """alpha* against the static load F~ (left) and the persistence against F~ per alpha (right)."""
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    groups = sorted({(t["a_over_g"], t["gravity"]) for t in table})
    amin = min(r["alpha"] for r in rows)
    amax = max(r["alpha"] for r in rows)
    for j, (ag, g) in enumerate(groups):
        sel = sorted((t for t in table if t["a_over_g"] == ag and t["gravity"] == g), key=lambda t: t["static_load"])
        pts_ = [t for t in sel if t["alpha_star"] is not None]
        if pts_:
            yerr = [max(t["err"] or 0, t["boot_std"] or 0) for t in pts_]
            ax.errorbar([t["static_load"] for t in pts_], [t["alpha_star"] for t in pts_], yerr=yerr, fmt="o-",
                        color=f"C{j}", capsize=3, label=f"a/g = {ag:.3g}, g = {g:g}")
    ax.axhline(100, ls="--", color="0.5", lw=0.8, label="paper: alpha* ~ 100 at a/g ~ 1")
    ax.set_yscale("log")
    top = max(amax * 1.5, 150.0)  # the paper's alpha* stays in view
    ax.set_ylim(amin / 1.5, top)
    ax.set_xlabel("static load F~ (rod weights)")
    ax.set_ylabel("alpha* (half the seeds stable)")
    ax.set_title("critical aspect ratio against static load", fontsize=9)
    ax.legend(fontsize=7)
    for k, a in enumerate(sorted({r["alpha"] for r in rows})):
        sel = [r for r in rows if r["alpha"] == a and r.get("persistence") is not None]
        if not sel:
            continue
        loads, mean, _ = _mean_by(sel, "static_load", "persistence")
        bx.scatter([r["static_load"] for r in sel], [r["persistence"] for r in sel], color=f"C{k}", s=12, alpha=0.6)
        bx.plot(loads, mean, "-", color=f"C{k}", label=f"alpha = {a:g}")
    all_loads = sorted({r["static_load"] for r in rows})
    for axis in (ax, bx):
        axis.set_xscale("symlog", linthresh=0.5)
        axis.set_xlim(-0.15, 1.5 * max(all_loads))
        axis.set_xticks(all_loads)
        axis.set_xticklabels([f"{s:g}" for s in all_loads])
        axis.minorticks_off()
    ax.set_yticks([t for t in (10, 20, 30, 50, 100, 200, 300) if amin / 1.5 <= t <= top])
    ax.set_yticklabels([f"{t:g}" for t in ax.get_yticks()])
    bx.set_ylim(0, 1.05)
    bx.set_xlabel("static load F~ (rod weights)")
    bx.set_ylabel("persistence tau (seeds; line: mean)")
    bx.set_title("how long each alpha stays entangled under load", fontsize=9)
    bx.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=DPI)
    plt.close(fig)
    return path
