"""The entanglement phase diagram of a sweep: the alpha* estimate and the figures.

Reads a sweep directory's ``results.csv`` (written by :func:`rodwarp.experiments.run_sweep`)
and draws the seed paper's phase-diagram figures from its ``ok`` rows: Fig. 4L (cv_e against
a/g, coloured by the verdict), Fig. 4H (f against alpha), Fig. 4I (f against a/g), the
verdict's measures against alpha, and the critical aspect ratio alpha* per a/g with its
uncertainty (``alpha_star.csv``; docs/protocol.md, "The verdict").
"""

from __future__ import annotations

import csv
import io
import itertools
import math
from pathlib import Path

from rodwarp.errors import RodwarpError
from rodwarp.experiments._plan import ENTANGLE, TEST
from rodwarp.experiments._sweep import _cell, read_results
from rodwarp.rodset.files import save_figure, write_text

#: colours of stable and unstable points
BLUE, RED = "#1f5fbf", "#c62828"
#: resolution of the phase-diagram PNGs (dots per inch)
DPI = 120


#: columns of results.csv the phase diagram reads (besides a_over_g, or freq and amplitude to compute it)
PHASE_COLUMNS = ("id", "alpha", "gravity", "largest_cluster_fraction", "stable", "status")
#: numeric columns of an ``ok`` row, with the range its value must lie in: (low, low included,
#: high); the limits are those ``rodwarp sweep`` checks (alpha > 1, gravity > 0, ...) and
#: those of the measures (fractions in [0, 1]). A value outside, not a number, or not finite
#: (NaN alpha, infinite a/g) would be drawn or interpolated as if measured.
_VALUES = {"alpha": (1.0, False, None), "freq": (0.0, True, None), "gravity": (0.0, False, None),
           "static_load": (0.0, True, None), "seed": (0.0, True, None), "amplitude": (0.0, True, None),
           "a_over_g": (0.0, True, None), "largest_cluster_fraction": (0.0, True, 1.0),
           "height_kept": (0.0, True, None), "persistence": (0.0, True, 1.0), "rods_left": (0.0, True, 1.0),
           "contacts_per_rod": (0.0, True, None), "cv_e": (0.0, True, None)}
#: columns an ``ok`` row must fill: without them a point has no place in the diagram
#: (a_over_g may be empty when freq, amplitude and gravity give it)
_NEEDED = ("alpha", "gravity", "largest_cluster_fraction")
#: spellings of the verdict (``rodwarp sweep`` writes True and False)
_VERDICTS = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}


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


def _refuse(csv_path, i: int, r: dict, why: str):
    pid = r.get("id") or ""
    raise RodwarpError(f"{csv_path} data row {i} (point {pid!r}): {why}; results.csv holds only what `rodwarp sweep` "
                       f"writes: fix or remove that row, or rerun the sweep into a clean folder")


def _value(csv_path, i: int, r: dict, k: str):
    """The number in column ``k`` of row ``r`` (None when empty), or a one-line refusal naming
    the row's id, the column and the value."""
    s = r.get(k)
    if s is None or s.strip() == "":
        return None
    try:
        v = float(s)
    except ValueError:
        _refuse(csv_path, i, r, f"{k} = {s!r} is not a number")
    if not math.isfinite(v):
        _refuse(csv_path, i, r, f"{k} = {s!r} is not a finite number")
    lo, lo_in, hi = _VALUES[k]
    if v < lo or (v == lo and not lo_in) or (hi is not None and v > hi):
        rng = f"{'>=' if lo_in else '>'} {lo:g}" + (f" and <= {hi:g}" if hi is not None else "")
        _refuse(csv_path, i, r, f"{k} = {s} is out of range (must be {rng})")
    return v


def _check_duplicates(csv_path, raw: list[dict]) -> None:
    """Refuse two rows of one point id: their verdicts would both count as seeds of that point
    (opposite ones put alpha* where the sweep measured nothing). ``run_sweep`` writes one row
    per id, so a duplicate comes from a hand edit or concatenated files."""
    by_id: dict = {}
    for i, r in enumerate(raw, 1):
        if r.get("id"):
            by_id.setdefault(r["id"], []).append((i, r))
    for pid, rs in by_id.items():
        if len(rs) > 1:
            def verdict(r):
                if r.get("status") != "ok":
                    return "failed"
                v = _VERDICTS.get(str(r.get("stable")).strip().lower())
                return {True: "stable", False: "unstable"}.get(v, f"stable = {r.get('stable')!r}")
            what = ", ".join(f"data row {i}: {verdict(r)}" for i, r in rs)
            raise RodwarpError(f"{csv_path} has {len(rs)} rows of point {pid!r} ({what}); a point has one row, "
                               f"and alpha* would count both: remove the duplicate rows, or rerun the sweep into "
                               f"a clean folder")


def _phase_rows(out) -> tuple[list[dict], list[dict]]:
    """The ``ok`` rows of ``out/results.csv`` as numbers, and the failed rows (skipped).

    Returns
    -------
    rows : list of dict
        One per ``ok`` row: the numeric columns (None where empty and optional), ``ag`` (a/g
        to 4 digits, the group key), ``stable`` (bool) and ``id``.
    failed : list of dict
        The rows whose ``status`` is not ``ok`` (a point that failed: it has no results).

    Raises
    ------
    RodwarpError
        One line naming the row's id and the column, for an ``ok`` row with a value that is
        not a finite number in range, an empty needed column, a verdict other than True or
        False, or an id that is not a folder name; for two rows of one id; for a file
        :func:`~rodwarp.experiments.read_results` refuses (not UTF-8, missing columns).
    """
    csv_path = Path(out) / "results.csv"
    raw = read_results(csv_path, required=PHASE_COLUMNS)
    if raw and "a_over_g" not in raw[0] and not {"freq", "amplitude"} <= set(raw[0]):
        raise RodwarpError(f"{csv_path} lacks the column a_over_g (or freq and amplitude, which give it); "
                           f"results.csv holds only what `rodwarp sweep` writes: restore it, or rerun the sweep "
                           f"into a clean folder")
    _check_duplicates(csv_path, raw)
    rows, failed = [], []
    for i, r in enumerate(raw, 1):
        if r.get("status") != "ok":
            failed.append(r)
            continue
        pid = r.get("id") or ""
        # the id names the point's folder, read for its time series and fields
        if not pid or pid in (".", "..") or any(c in pid for c in "/\\\0"):
            _refuse(csv_path, i, r, f"id {pid!r} is not a point's folder name")
        d = {k: _value(csv_path, i, r, k) for k in _VALUES}
        for k in _NEEDED:
            if d[k] is None:
                _refuse(csv_path, i, r, f"{k} is empty")
        if d["a_over_g"] is None:
            if d["freq"] is None or d["amplitude"] is None:
                _refuse(csv_path, i, r, "a_over_g is empty, and so is freq or amplitude, which give it")
            d["a_over_g"] = 4 * math.pi**2 * d["freq"] ** 2 * d["amplitude"] / d["gravity"]
        d["static_load"] = d["static_load"] or 0.0
        verdict = _VERDICTS.get(str(r.get("stable")).strip().lower())
        if verdict is None:
            _refuse(csv_path, i, r, f"stable = {r.get('stable')!r} is not True or False")
        d["stable"] = verdict
        d["id"] = pid
        d["ag"] = float(f"{d['a_over_g']:.4g}")
        rows.append(d)
    return rows, failed


def _ok_rows(out) -> list[dict]:
    """The ``ok`` rows of ``out/results.csv`` (see :func:`_phase_rows`)."""
    return _phase_rows(out)[0]


def _crossing(xs, ys, level=0.5):
    """First upward crossing of ``level`` by ys(xs), interpolated in log x.

    Returns (x*, err, lo, hi, note): err = half the bracketing interval; when no crossing,
    x* is None and the note says on which side of the range it lies.
    """
    pairs = sorted(zip(xs, ys))
    xs = [p[0] for p in pairs]
    ys = [p[1] for p in pairs]
    if all(y >= level for y in ys):
        return None, None, None, xs[0], f"below {xs[0]:g} (all points at or above {level:g})"
    if all(y < level for y in ys):
        return None, None, xs[-1], None, f"above {xs[-1]:g} (all points below {level:g})"
    # the last crossing from below (beyond it every point is at or above the level)
    i = max(j for j in range(len(ys)) if ys[j] < level)
    if i == len(ys) - 1:
        return None, None, xs[-1], None, f"above {xs[-1]:g} (largest alpha below {level:g})"
    x0, x1, y0, y1 = xs[i], xs[i + 1], ys[i], ys[i + 1]
    t = (level - y0) / (y1 - y0) if y1 != y0 else 0.5
    x = math.exp(math.log(x0) + t * (math.log(x1) - math.log(x0)))
    note = "interpolated" if all(y >= level for y in ys[i + 1:]) and all(y < level for y in ys[:i + 1]) \
        else "interpolated (non-monotonic: last crossing)"
    return x, 0.5 * (x1 - x0), x0, x1, note


def _bracketed(alphas, by_alpha, value, rng, n_boot):
    """Crossing of 0.5 by the seed mean of ``value(row)`` against alpha, with a bootstrap over seeds."""
    mean = [sum(value(r) for r in by_alpha[a]) / len(by_alpha[a]) for a in alphas]
    x, err, lo, hi, note = _crossing(alphas, mean)
    boot = None
    if max(len(v) for v in by_alpha.values()) > 1 and x is not None:
        vals = []
        for _ in range(n_boot):
            bm = [sum(value(rng.choice(by_alpha[a])) for _ in by_alpha[a]) / len(by_alpha[a]) for a in alphas]
            bx = _crossing(alphas, bm)[0]
            if bx is not None:
                vals.append(math.log(bx))
        if len(vals) > 1:
            m = sum(vals) / len(vals)
            boot = x * (sum((v - m) ** 2 for v in vals) / (len(vals) - 1)) ** 0.5  # log spread in alpha units
    return x, err, lo, hi, boot, note


def alpha_star(rows: list[dict], n_boot: int = 200, seed: int = 0) -> list[dict]:
    """Critical aspect ratio for each (a/g, gravity, static load) from ok rows (see :func:`_ok_rows`).

    ``alpha_star``: where the fraction of seeds judged ``stable`` (the verdict of
    :mod:`rodwarp.verdict`: height kept, persistence and the contact cluster) crosses 1/2,
    interpolated in log alpha; ``err`` is half the bracketing interval, ``boot_std`` the
    bootstrap spread over seeds (when a point has several). ``alpha_star_f``: the same on
    the seed-mean largest-cluster fraction f crossing 0.5 (the paper's Fig. 4H measure).
    """
    import random

    rng = random.Random(seed)
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["ag"], r["gravity"], r["static_load"]), []).append(r)
    out = []
    for (ag, g, s), rs in sorted(groups.items(), key=lambda kv: (kv[0][2], kv[0][1], kv[0][0])):
        by_alpha: dict = {}
        for r in rs:
            by_alpha.setdefault(r["alpha"], []).append(r)
        alphas = sorted(by_alpha)
        nseeds = max(len(v) for v in by_alpha.values())
        x, err, lo, hi, boot, note = _bracketed(alphas, by_alpha, lambda r: float(r["stable"]), rng, n_boot)
        xf, errf, lof, hif, bootf, notef = _bracketed(alphas, by_alpha, lambda r: r["largest_cluster_fraction"],
                                                     rng, n_boot)
        out.append({"a_over_g": ag, "gravity": g, "static_load": s, "n_alphas": len(alphas), "seeds": nseeds,
                    "alpha_star": x, "err": err, "bracket_lo": lo, "bracket_hi": hi, "boot_std": boot, "note": note,
                    "alpha_star_f": xf, "err_f": errf, "bracket_lo_f": lof, "bracket_hi_f": hif,
                    "boot_std_f": bootf, "note_f": notef})
    return out


def phase_diagram(out, note=None) -> list[Path]:
    """Figures and the alpha* table of a sweep directory (reads ``out/results.csv``).

    Writes ``phase_cv_e.png`` (Fig. 4L: sigma_e/mu_e against a/g, coloured by stability, with
    shaded stable/unstable regions), ``phase_f_alpha.png`` (Fig. 4H: f against alpha for each
    a/g), ``phase_verdict_alpha.png`` (height kept and persistence against alpha, the verdict's
    thresholds drawn), ``phase_f_ag.png`` (Fig. 4I: f against a/g for each alpha and static load),
    ``alpha_star.csv`` and ``phase_alpha_star.png`` (alpha* against a/g with its uncertainty),
    ``phase_alpha_star_load.png`` when the sweep has several static loads (alpha* against F~ at
    each a/g, with the persistence of every alpha: Fig. 4I's question, does a load move the
    transition), and from each point's own files: ``phase_timeseries*.png`` (Fig. 4C-D: Z(t), f(t) and
    cv_e(t) per alpha, from its metrics.csv) and ``phase_distributions*.png`` with
    ``power_law.csv`` (Fig. 4E-F: p(e) and p(c) per alpha, pooled over seeds, and their fitted
    power-law tails, from its analysis/fields.zarr); one of each per (a/g, g, F~) group, the
    group in the name when there are several. Returns the paths written.

    Only the ``ok`` rows are drawn; a failed point's row (``status`` not ``ok``) is skipped,
    and ``note`` (a callable of one string, optional) is told how many. A row that cannot be
    a measurement (a value that is not a finite number in range, two rows of one point, a
    file that is not a UTF-8 CSV with the needed columns) is refused with a one-line
    :class:`~rodwarp.errors.RodwarpError` naming it (see :func:`_phase_rows`).
    """
    import matplotlib

    matplotlib.use("Agg")

    out = Path(out)
    rows, failed = _phase_rows(out)
    skipped = ""
    if failed:
        first = failed[0]
        status = " ".join(str(first.get("status") or "no status").split())[:120]
        skipped = (f"{len(failed)} failed row(s) skipped (status not 'ok'; the first: "
                   f"{first.get('id') or '?'}: {status})")
    if not rows:
        raise RodwarpError(f"{out / 'results.csv'} has no 'ok' rows with results"
                           f"{' (' + skipped + ')' if skipped else ''}: nothing to plot")
    if skipped and note is not None:
        note(f"{out / 'results.csv'}: {skipped}")
    written = [_cv_e_figure(rows, out / "phase_cv_e.png"), _f_alpha_figure(rows, out / "phase_f_alpha.png")]
    if any(r["height_kept"] is not None for r in rows):
        written.append(_verdict_figure(rows, out / "phase_verdict_alpha.png"))
    written.append(_f_ag_figure(rows, out / "phase_f_ag.png"))
    table = alpha_star(rows)
    written.append(_write_table(table, out / "alpha_star.csv"))
    written.append(_alpha_star_figure(rows, table, out / "phase_alpha_star.png"))
    if len({t["static_load"] for t in table}) > 1:
        written.append(_alpha_star_load_figure(rows, table, out / "phase_alpha_star_load.png"))
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["ag"], r["gravity"], r["static_load"]), []).append(r)
    fits = []
    for key, rs in sorted(groups.items()):
        tag = "" if len(groups) == 1 else f"_ag{key[0]:g}_g{key[1]:g}_F{key[2]:g}"
        p = _timeseries_figure(out, key, rs, out / f"phase_timeseries{tag}.png")
        if p is not None:
            written.append(p)
        p, f = _distributions_figure(out, key, rs, out / f"phase_distributions{tag}.png")
        if p is not None:
            written.append(p)
        fits += f
    if fits:
        written.append(_write_table(fits, out / "power_law.csv"))
    return written


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


def _write_table(table: list[dict], path: Path) -> Path:
    """A CSV of dict rows (``alpha_star.csv``: one per (a/g, gravity, static load) of
    :func:`alpha_star`; ``power_law.csv``); columns: every key, in order of appearance."""
    buf = io.StringIO()
    names = list(dict.fromkeys(k for t in table for k in t))
    w = csv.DictWriter(buf, fieldnames=names, lineterminator="\n")
    w.writeheader()
    for t in table:
        w.writerow({k: _cell(v) for k, v in t.items()})
    write_text(path, buf.getvalue())
    return path


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
