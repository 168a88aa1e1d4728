"""The entanglement phase diagram of a sweep: the rows it reads, the alpha* estimate, the driver.

Reads a sweep directory's ``results.csv`` (written by :func:`rodwarp.experiments.run_sweep`),
refusing a row that cannot be a measurement, and estimates from its ``ok`` rows the critical
aspect ratio alpha* per a/g with its uncertainty (``alpha_star.csv``; docs/protocol.md, "The
verdict"). :func:`phase_diagram` writes the table and the seed paper's phase-diagram figures,
drawn in :mod:`rodwarp.experiments._phase_figures`: Fig. 4L (cv_e against a/g, coloured by the
verdict), Fig. 4H (f against alpha), Fig. 4I (f against a/g), the verdict's measures against
alpha, alpha* against a/g, and from each point's own files Fig. 4C-F.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

from rodwarp.errors import RodwarpError
from rodwarp.experiments._phase_figures import (_alpha_star_figure, _alpha_star_load_figure, _cv_e_figure,
                                                _distributions_figure, _f_ag_figure, _f_alpha_figure,
                                                _timeseries_figure, _verdict_figure)
from rodwarp.experiments._sweep import _cell, read_results
from rodwarp.rodset.files import write_text

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


def phase_diagram(out, note=None, dest=None, progress: bool | None = None) -> list[Path]:
    """Figures and the alpha* table of a sweep directory (reads ``out/results.csv``).

    They are written into ``dest`` (default ``out``, the sweep's folder); the points' own files
    are read from ``out`` either way.

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
    :class:`~rodwarp.errors.RodwarpError` naming it (see :func:`_phase_rows`), before anything
    is drawn. Drawing a large sweep takes seconds: with ``progress`` (None: unless the process
    is quiet, :func:`rodwarp._util.quiet`) a note on stderr says so once it has run
    :data:`rodwarp._util.NOTE_AFTER_S`.
    """
    from rodwarp._util import slow_phase

    out = Path(out)
    dest = out if dest is None else Path(dest)
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
    with slow_phase(f"drawing the phase diagram of {len(rows)} points", enabled=progress):
        return _draw(out, dest, rows)


def _draw(out: Path, dest: Path, rows: list[dict]) -> list[Path]:
    """The files of :func:`phase_diagram` from the checked ``ok`` rows, written into ``dest``
    (the points' own files read from ``out``); returns their paths."""
    import matplotlib

    matplotlib.use("Agg")

    written = [_cv_e_figure(rows, dest / "phase_cv_e.png"), _f_alpha_figure(rows, dest / "phase_f_alpha.png")]
    if any(r["height_kept"] is not None for r in rows):
        written.append(_verdict_figure(rows, dest / "phase_verdict_alpha.png"))
    written.append(_f_ag_figure(rows, dest / "phase_f_ag.png"))
    table = alpha_star(rows)
    written.append(_write_table(table, dest / "alpha_star.csv"))
    written.append(_alpha_star_figure(rows, table, dest / "phase_alpha_star.png"))
    if len({t["static_load"] for t in table}) > 1:
        written.append(_alpha_star_load_figure(rows, table, dest / "phase_alpha_star_load.png"))
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["ag"], r["gravity"], r["static_load"]), []).append(r)
    fits = []
    for key, rs in sorted(groups.items()):
        tag = "" if len(groups) == 1 else f"_ag{key[0]:g}_g{key[1]:g}_F{key[2]:g}"
        p = _timeseries_figure(out, key, rs, dest / f"phase_timeseries{tag}.png")
        if p is not None:
            written.append(p)
        p, f = _distributions_figure(out, key, rs, dest / f"phase_distributions{tag}.png")
        if p is not None:
            written.append(p)
        fits += f
    if fits:
        written.append(_write_table(fits, dest / "power_law.csv"))
    return written


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
