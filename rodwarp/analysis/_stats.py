"""Statistics of the mesoscopic fields: moments, outlier bound, tangles, histograms, z profiles.

NumPy/SciPy only, so the statistics stage runs wherever the fields can be read (no Warp).

Conventions
    Field arrays have axis order (z, y, x), like :class:`rodwarp.analysis.Fields`; everything
    reported per axis (extents, bounding boxes, percolation) is in (x, y, z) order.
    Lengths are in the units of the fields (``Fields.units``: m, mm, um or CT voxels).

The paper (Jung et al., "Entanglement transition in random rod packings") calls voxels with
``e > e_lb`` outliers and their connected clusters *tangles*; it compares the tangle bounding-box
sizes xi_x, xi_y, xi_z with the system size and uses sigma_e / mu_e as its order parameter.
``docs/fields.md`` gives the outlier bound, its Q1/Q3 variants and the authors' cluster bug.
Which fields get a mean, a histogram and a z-profile is the field registry's to say
(:data:`rodwarp.analysis.FIELDS`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from rodwarp._util import json_safe
from rodwarp.analysis._fieldset import Fields
from rodwarp.analysis._registry import fields_with
from rodwarp.errors import RodwarpError, RodwarpTypeError
from rodwarp.arguments import instance, real, whole

__all__ = ["outlier_bound", "find_tangles", "histogram", "z_profiles", "field_statistics", "power_law_fit",
           "power_law_density", "log_histogram",
           "AXES"]

AXES = ("x", "y", "z")
# Array axis of each reported axis: arrays are (z, y, x).
_ARRAY_AXIS = {"x": 2, "y": 1, "z": 0}
_MAX_TANGLES_REPORTED = 50
#: most histogram bins, as ``rodwarp analyze --bins``
MAX_BINS = 100_000


# ----------------------------------------------------------------------------------------------
# outlier bound
# ----------------------------------------------------------------------------------------------

def outlier_bound(values, method: str = "q3") -> dict[str, float]:
    """Lower bound ``e_lb`` above which values count as (upper) outliers.

    Parameters
    ----------
    values : array_like
        Sample, any shape (e.g. the entanglement field, dimensionless). NaN and inf are
        ignored, so a field with NaN outside the domain can be passed as is.
    method : {"q3", "q1"}
        ``"q3"``: ``e_lb = Q3 + 1.5 IQR`` - Tukey's upper fence, as in the paper's Fig. 2
        caption and the authors' code (the default). ``"q1"``: ``e_lb = Q1 + 1.5 IQR``, the
        variant printed in the paper's text (most likely a typo; kept to compare).

    Returns
    -------
    dict
        ``e_lb``, ``q1``, ``q3``, ``iqr`` (same units as ``values``). Quartiles use linear
        interpolation between order statistics (NumPy's default percentile method); MATLAB's
        ``quantile`` places the i-th order statistic at (i - 0.5) / n instead, so a bound from
        MATLAB can differ slightly on small samples.

    Raises
    ------
    RodwarpError
        Unknown ``method``, or no finite value to take quartiles of.
    """
    if method not in ("q3", "q1"):
        raise RodwarpError(f"unknown outlier method '{method}': use 'q3' (Q3 + 1.5 IQR) or 'q1' (Q1 + 1.5 IQR)")
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise RodwarpError("cannot compute an outlier bound: no finite values")
    q1, q3 = np.percentile(v, [25.0, 75.0])
    iqr = q3 - q1
    base = q3 if method == "q3" else q1
    return {"e_lb": float(base + 1.5 * iqr), "q1": float(q1), "q3": float(q3), "iqr": float(iqr)}


# ----------------------------------------------------------------------------------------------
# tangles
# ----------------------------------------------------------------------------------------------

def _structure(connectivity: int) -> np.ndarray:
    if connectivity == 26:
        return np.ones((3, 3, 3), dtype=bool)
    if connectivity == 6:
        return ndimage.generate_binary_structure(3, 1)
    raise RodwarpError(f"connectivity must be 26 (faces, edges and corners) or 6 (faces only), got {connectivity!r}")


def _per_axis(value, name: str) -> np.ndarray:
    """A scalar or an (x, y, z) triple as a float array of 3."""
    a = np.asarray(value, dtype=np.float64).reshape(-1)
    if a.size == 1:
        a = np.repeat(a, 3)
    if a.size != 3 or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise RodwarpError(f"{name} must be a positive number or three positive numbers (x, y, z), got {value!r}")
    return a


def _valid_bbox(valid: np.ndarray) -> dict[str, tuple[int, int]]:
    """Inclusive index range of the valid voxels along each axis (x, y, z order)."""
    out = {}
    for ax in AXES:
        k = _ARRAY_AXIS[ax]
        other = tuple(i for i in range(3) if i != k)
        idx = np.flatnonzero(valid.any(axis=other))
        out[ax] = (int(idx[0]), int(idx[-1]))
    return out


def find_tangles(e, valid, e_lb: float, connectivity: int = 26, spacing=1.0, system_size=None):
    """Label the tangles: connected clusters of valid voxels with ``e > e_lb``.

    Parameters
    ----------
    e : ndarray, shape (nz, ny, nx)
        Entanglement field (dimensionless); NaN voxels are never outliers.
    valid : ndarray of bool, shape (nz, ny, nx)
        Voxels inside the analysed domain (``Fields.valid``).
    e_lb : float
        Outlier bound, finite (see :func:`outlier_bound`); the comparison is strict.
    connectivity : {26, 6}
        26: voxels touching by a face, an edge or a corner belong together (full 3x3x3
        structure); 6: faces only.
    spacing : float or sequence of 3 floats
        Grid spacing, in length units; a triple is (x, y, z).
    system_size : sequence of 3 floats, optional
        System size L (x, y, z) in length units. Default: the bounding box of the valid voxels,
        ``(index span + 1) * spacing`` per axis - the same as ``Fields.system_size``.

    Returns
    -------
    labels : ndarray of int32, shape (nz, ny, nx)
        0 outside tangles; tangle k (1-based) is the k-th largest, so label 1 is the largest.
    tangles : list of dict
        One per tangle, sorted by size descending (ties: lower position in scan order first).
        ``share`` divides by the valid voxels, not by the whole grid as the paper's text does,
        so that a grid padded around the packing does not shrink it:

        ``label`` (int, as in ``labels``), ``n_voxels`` (int), ``share`` (n_voxels / number of
        valid voxels), ``bbox`` ({axis: [lo, hi]} inclusive voxel indices), ``xi`` ({axis:
        extent in length units} = (hi - lo + 1) * spacing), ``xi_over_L`` ({axis: xi / L}),
        ``touches`` ({"x-", "x+", "y-", ...: bool}, whether the tangle reaches that face of the
        valid voxels' bounding box), ``percolates_axes`` (axes with both faces touched) and
        ``percolates`` (bool).

    Raises
    ------
    RodwarpError
        Shapes that do not match, a connectivity other than 26 or 6, a bad spacing or size.
    """
    structure = _structure(connectivity)
    e_lb = real("e_lb", e_lb, hint="the outlier bound of outlier_bound()")
    e = np.asarray(e, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool)
    if e.ndim != 3 or e.shape != valid.shape:
        raise RodwarpError(f"e and valid must be 3-D arrays of one shape (z, y, x), got {e.shape} and {valid.shape}")
    h = _per_axis(spacing, "spacing")
    n_valid = int(valid.sum())
    if n_valid == 0:
        return np.zeros(e.shape, dtype=np.int32), []
    vbox = _valid_bbox(valid)
    if system_size is None:
        L = np.array([(vbox[ax][1] - vbox[ax][0] + 1) * h[k] for k, ax in enumerate(AXES)])
    else:
        L = _per_axis(system_size, "system_size")

    # NaN > e_lb is already False; the explicit isfinite guards inf and documents intent.
    with np.errstate(invalid="ignore"):
        outlier = valid & np.isfinite(e) & (e > e_lb)
    raw, n = ndimage.label(outlier, structure=structure)
    if n == 0:
        return np.zeros(e.shape, dtype=np.int32), []

    counts = np.bincount(raw.ravel(), minlength=n + 1)
    # find_objects returns one slice tuple per label 1..n - all of them. (The authors' cluster
    # loop ran over 1..n-1 and silently dropped the last tangle.)
    slices = ndimage.find_objects(raw)
    order = sorted(range(1, n + 1), key=lambda lab: (-counts[lab], lab))
    lut = np.zeros(n + 1, dtype=np.int32)
    lut[order] = np.arange(1, n + 1, dtype=np.int32)
    labels = lut[raw]

    tangles = []
    for new, old in enumerate(order, start=1):
        sl = slices[old - 1]
        bbox, xi, xi_over_L, touches, perc = {}, {}, {}, {}, []
        for k, ax in enumerate(AXES):
            s = sl[_ARRAY_AXIS[ax]]
            lo, hi = int(s.start), int(s.stop - 1)
            bbox[ax] = [lo, hi]
            xi[ax] = float((hi - lo + 1) * h[k])
            xi_over_L[ax] = float(xi[ax] / L[k])
            touches[f"{ax}-"] = lo <= vbox[ax][0]
            touches[f"{ax}+"] = hi >= vbox[ax][1]
            if touches[f"{ax}-"] and touches[f"{ax}+"]:
                perc.append(ax)
        tangles.append({
            "label": new,
            "n_voxels": int(counts[old]),
            "share": float(counts[old] / n_valid),
            "bbox": bbox,
            "xi": xi,
            "xi_over_L": xi_over_L,
            "touches": touches,
            "percolates_axes": perc,
            "percolates": bool(perc),
        })
    return labels, tangles


# ----------------------------------------------------------------------------------------------
# histograms and profiles
# ----------------------------------------------------------------------------------------------

def histogram(values, bins: int = 40, range=None) -> dict[str, np.ndarray]:  # noqa: A002 - numpy's name
    """Histogram of the finite values.

    Parameters
    ----------
    values : array_like
        Sample (field values, any shape); NaN and inf are dropped.
    bins : int
        Number of equal-width bins, 1 to ``MAX_BINS``.
    range : (float, float), optional
        Lower and upper edge (finite, lower below upper); default the min and max of the
        finite values.

    Returns
    -------
    dict
        ``edges`` (bins + 1, in the units of ``values``), ``counts`` (int), ``density``
        (counts / (n * bin width), in 1 / units of ``values``; integrates to 1 over the range;
        NaN when there is no finite value) and ``n`` (finite values counted, inside or outside
        the range).
    """
    bins = whole("bins", bins, ge=1, le=MAX_BINS)
    if range is not None:
        range = _range(range)
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if range is None and v.size and 0 < v.max() - v.min() < 1e-9 * max(1.0, abs(v.max()), abs(v.min())):
        # values equal but for rounding (a field constant over the packing): NumPy cannot cut
        # so narrow a range into `bins` finite bins, so centre a range of a relative 1e-6 on them
        c = 0.5 * (v.max() + v.min())
        half = 1e-6 * max(abs(c), 1e-12)
        range = (c - half, c + half)
    counts, edges = np.histogram(v, bins=bins, range=range)
    total = counts.sum()
    widths = np.diff(edges)
    if total > 0:
        density = counts / (total * widths)
    else:
        # no sample: a density is undefined, and NaN says so without a divide warning
        density = np.full(counts.shape, np.nan)
    return {"edges": edges, "counts": counts, "density": density, "n": int(v.size)}


def _range(value) -> tuple[float, float]:
    """A histogram's (lower, upper) edges: two finite numbers, lower below upper."""
    try:
        lo, hi = value
    except (TypeError, ValueError):
        raise RodwarpTypeError(f"range must be two numbers (lower, upper) or None, got {value!r}") from None
    lo, hi = real("range lower edge", lo), real("range upper edge", hi)
    if not lo < hi:
        raise RodwarpError(f"range lower edge {lo:g} must be below its upper edge {hi:g}")
    return lo, hi


def _truncated_gamma(logx: np.ndarray, la: float, lb: float) -> float:
    """Maximum-likelihood exponent of p(x) ~ x^-gamma on [a, b] (logs given), by a bounded scalar solve."""
    from scipy.optimize import minimize_scalar

    n = logx.size
    s = logx.sum()
    span = lb - la

    def nll(g):
        # log of Z(g) = integral of x^-g over [a, b], written to stay finite near g = 1
        q = (1.0 - g) * span
        if abs(q) < 1e-8:
            logz = la + np.log(span)
        elif q > 0:
            logz = (1.0 - g) * la + np.log(np.expm1(q) / (1.0 - g))
        else:
            logz = (1.0 - g) * lb + np.log(-np.expm1(-q) / (1.0 - g))
        return g * s + n * logz

    return float(minimize_scalar(nll, bounds=(-5.0, 15.0), method="bounded", options={"xatol": 1e-6}).x)


def _truncated_cdf(x: np.ndarray, a: float, b: float, g: float) -> np.ndarray:
    if abs(g - 1.0) < 1e-9:
        return np.log(x / a) / np.log(b / a)
    return (x ** (1.0 - g) - a ** (1.0 - g)) / (b ** (1.0 - g) - a ** (1.0 - g))


def power_law_fit(values, *, min_range: int = 50, candidates: int = 24) -> dict | None:
    """The widest range [x_min, x_max] over which the sample follows p(x) ~ x^-gamma, and gamma.

    For every pair of candidate bounds (log-spaced quantiles of the positive sample) holding at
    least ``min_range`` values, gamma is the maximum-likelihood exponent of a power law
    truncated to [x_min, x_max] and the fit is accepted when its Kolmogorov-Smirnov distance is
    below the 5% critical value 1.36 / sqrt(n) (the power law is not rejected there); the
    accepted range spanning the most decades wins (without any accepted, the closest fit).
    The bounds are part of the answer: a field's distribution is a power law over a range,
    cut off by the finite ball and rod sizes (Clauset, Shalizi & Newman 2009 for the
    estimator; the range test is theirs with an upper bound).

    Parameters
    ----------
    values : array_like
        Sample (e.g. a field's valid voxels); non-finite and non-positive values are dropped.
    min_range : int
        Fewest samples a range may hold (>= 2).
    candidates : int
        Candidate bounds tried on each side (1 to 1000).

    Returns
    -------
    dict or None
        ``gamma`` (exponent of the density), ``gamma_err`` = |gamma - 1| / sqrt(n) + 1 / sqrt(n)
        (the estimator's standard error for independent samples; voxels of overlapping balls
        are correlated, so the true uncertainty is larger), ``xmin``, ``xmax``, ``decades``
        (log10 xmax / xmin), ``n_range`` (samples inside), ``range_fraction``, ``ks``,
        ``accepted`` (the KS test passed) and ``note`` (says when the range spans less than one
        decade, or no range passed); None when fewer than ``min_range`` positive values exist.
    """
    min_range = whole("min_range", min_range, ge=2)
    candidates = whole("candidates", candidates, ge=1, le=1000, hint="the fit tries candidates^2 ranges")
    v = np.asarray(values, dtype=np.float64).ravel()
    v = np.sort(v[np.isfinite(v) & (v > 0)])
    n = v.size
    if n < min_range or v[-1] <= v[0]:
        return None
    lv = np.log(v)
    bounds = np.unique(np.exp(np.linspace(lv[0], lv[-1], candidates + 1)))
    best = None  # (accepted, decades, n_range, -ks) ordering
    for i, a in enumerate(bounds[:-1]):
        ia = np.searchsorted(v, a, side="left")
        for b in bounds[i + 1:]:
            ib = np.searchsorted(v, b, side="right")
            m = ib - ia
            if m < min_range:
                continue
            x = v[ia:ib]
            g = _truncated_gamma(lv[ia:ib], np.log(a), np.log(b))
            cdf = _truncated_cdf(x, a, b, g)
            emp = np.arange(1, m + 1) / m
            ks = float(np.max(np.maximum(np.abs(emp - cdf), np.abs(emp - 1.0 / m - cdf))))
            ok = ks <= 1.36 / np.sqrt(m)
            key = (ok, np.log10(b / a) if ok else -ks, m)
            if best is None or key > best[0]:
                best = (key, a, b, g, ks, m, ok)
    if best is None:
        return None
    _, a, b, g, ks, m, ok = best
    decades = float(np.log10(b / a))
    if not ok:
        note = "no range passes the KS test: not a power law"
    elif decades < 1.0:
        note = f"the power law spans {decades:.2f} decades: too narrow to call it one"
    else:
        note = ""
    return {"gamma": g, "gamma_err": float((abs(g - 1.0) + 1.0) / np.sqrt(m)), "xmin": float(a), "xmax": float(b),
            "decades": decades, "n_range": int(m), "range_fraction": float(m / n), "ks": ks, "accepted": bool(ok),
            "note": note}


def log_histogram(values, bins: int = 30) -> dict | None:
    """Density of the positive finite values in log-spaced bins (for log-log plots).

    Returns
    -------
    dict or None
        ``x`` (geometric bin centres) and ``density`` (counts / (n * bin width), in 1 / units
        of ``values``) of the non-empty bins; None with fewer than two distinct positive values.
    """
    bins = whole("bins", bins, ge=2, le=MAX_BINS, hint="log-spaced bin edges")
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v) & (v > 0)]
    if v.size < 2 or v.max() <= v.min():
        return None
    edges = np.geomspace(v.min(), v.max(), bins)
    counts, _ = np.histogram(v, bins=edges)
    dens = counts / (v.size * np.diff(edges))
    ok = dens > 0
    return {"x": np.sqrt(edges[1:] * edges[:-1])[ok], "density": dens[ok]}


def power_law_density(x, fit: dict) -> np.ndarray:
    """The fitted power law of :func:`power_law_fit` as a density of the whole sample at ``x``
    (inside its range: the range's share of the sample, x^-gamma normalised over the range)."""
    x = np.asarray(x, dtype=np.float64)
    g, a, b = fit["gamma"], fit["xmin"], fit["xmax"]
    z = np.log(b / a) if abs(g - 1.0) < 1e-9 else (b ** (1.0 - g) - a ** (1.0 - g)) / (1.0 - g)
    return fit["range_fraction"] * x ** -g / z


def z_profiles(fields) -> dict[str, np.ndarray]:
    """Horizontal (x, y) means of each field at every height z.

    Parameters
    ----------
    fields : rodwarp.analysis.Fields

    Returns
    -------
    dict
        ``z`` (voxel-centre heights, length units) and, for every field with a z-profile
        panel in the registry (phi, S, c, e, n, n_ends), an array of the
        mean over the valid voxels of each z layer whose value is finite (NaN where there is
        none), in the units of the field.
    """
    valid = fields.valid
    out = {"z": np.asarray(fields.z, dtype=np.float64).copy()}
    for name in (f.name for f in fields_with("zprofile")):
        a = fields.get(name)
        m = valid & np.isfinite(a)
        count = m.sum(axis=(1, 2))
        total = np.where(m, a, 0.0).sum(axis=(1, 2))
        prof = np.full(count.shape, np.nan)
        np.divide(total, count, out=prof, where=count > 0)
        out[name] = prof
    return out


# ----------------------------------------------------------------------------------------------
# summary
# ----------------------------------------------------------------------------------------------

def field_statistics(fields, method: str = "q3", connectivity: int = 26, bins: int = 40,
                     contact_cluster_fraction: float | None = None, power_laws: bool = True) -> dict[str, Any]:
    """Summary statistics of one set of fields, JSON-serialisable.

    Parameters
    ----------
    fields : rodwarp.analysis.Fields
        The fields; only voxels in ``fields.valid`` count.
    method : {"q3", "q1"}
        Outlier bound, see :func:`outlier_bound`.
    connectivity : {26, 6}
        Voxel connectivity of tangles, see :func:`find_tangles`.
    bins : int
        Bins of each histogram, 1 to ``MAX_BINS``.
    contact_cluster_fraction : float, optional
        Fraction of rods in [0, 1] in the largest contact cluster (the paper's stability measure f),
        when the caller has it; stored as ``largest_contact_cluster_fraction``.
    power_laws : bool
        Fit the power laws of p(e) and p(c) (``power_law``; about 0.1-1 s); False leaves
        them None.

    Returns
    -------
    dict
        The summary key of every field with a reducer in the registry (``mean_phi``,
        ``mean_S``, ``mean_c``, ``mean_e``, ``mean_n``, ``mean_n_ends``: means over valid voxels;
        None for a field with no finite valid value), ``std_e`` (population standard deviation),
        ``cv_e`` (= std_e / mean_e, the paper's sigma_e / mu_e; None when mean_e is 0),
        ``median_e``, ``e_lb``, ``q1_e``, ``q3_e``, ``iqr_e``, ``outlier_method``,
        ``n_outlier_voxels``, ``outlier_fraction`` (outlier voxels / valid voxels),
        ``n_valid_voxels``, ``valid_fraction`` (of the grid), ``shape`` (nz, ny, nx),
        ``spacing``, ``radius``, ``units``, ``system_size`` ({axis: L}), ``connectivity``,
        ``n_tangles``, ``largest_tangle_share``, ``largest_tangle_extent`` ({axis: xi / L} of
        the largest tangle, zeros when there is none), ``largest_tangle_xi`` ({axis: xi}),
        ``percolates`` (any tangle spans the system along some axis), ``percolating_axes``,
        ``tangles`` (the 50 largest, see :func:`find_tangles`), ``tangles_truncated``,
        ``histograms`` ({field: histogram as lists, or None} for the fields with a histogram
        panel), ``power_law`` ({"e", "c": :func:`power_law_fit` of the valid voxels' values, the
        tails of the paper's Fig. 4E-F}), ``z_profiles`` (lists, None for NaN) and
        ``largest_contact_cluster_fraction``. Lengths are in ``units``.

    Raises
    ------
    RodwarpError
        No valid voxel, or a bad method or connectivity.
    """
    instance("fields", fields, Fields, "a Fields object (compute_fields(rods) or Fields.load(path))")
    _structure(connectivity)  # fail on a bad connectivity before any work
    bins = whole("bins", bins, ge=1, le=MAX_BINS)
    if contact_cluster_fraction is not None:
        real("contact_cluster_fraction", contact_cluster_fraction, ge=0, le=1, hint="a fraction of the rods")
    valid = fields.valid
    n_valid = int(valid.sum())
    if n_valid == 0:
        raise RodwarpError("the fields have no valid voxel (finite e with n > 0); nothing to summarise")

    out: dict[str, Any] = {}
    samples = {}
    for spec in fields_with(reducer="mean"):
        a = fields.get(spec.name)
        v = a[valid & np.isfinite(a)]
        samples[spec.name] = v
        # an all-NaN field (not provided by the source) is "unknown", not a RuntimeWarning
        out[spec.summary] = float(v.mean()) if v.size else None
    hist_names = [f.name for f in fields_with("histogram")]
    for name in hist_names:
        if name not in samples:
            a = fields.get(name)
            samples[name] = a[valid & np.isfinite(a)]

    e = samples["e"]
    std_e = float(e.std())  # population (ddof = 0), as sigma_e in the paper
    mean_e = float(e.mean())
    out["std_e"] = std_e
    out["cv_e"] = std_e / mean_e if mean_e else None
    out["median_e"] = float(np.median(e))

    bound = outlier_bound(e, method)
    out.update(e_lb=bound["e_lb"], q1_e=bound["q1"], q3_e=bound["q3"], iqr_e=bound["iqr"], outlier_method=method)

    L = np.asarray(fields.system_size, dtype=np.float64)
    labels, tangles = find_tangles(fields.e, valid, bound["e_lb"], connectivity=connectivity,
                                   spacing=fields.spacing, system_size=L)
    n_out = int(np.count_nonzero(labels))
    out.update(
        n_outlier_voxels=n_out,
        outlier_fraction=n_out / n_valid,
        n_valid_voxels=n_valid,
        valid_fraction=n_valid / valid.size,
        shape=list(valid.shape),
        spacing=float(fields.spacing),
        radius=float(fields.radius),
        units=fields.units,
        system_size=dict(zip(AXES, L.tolist())),
        connectivity=connectivity,
        n_tangles=len(tangles),
    )
    if tangles:
        big = tangles[0]
        out["largest_tangle_share"] = big["share"]
        out["largest_tangle_extent"] = dict(big["xi_over_L"])
        out["largest_tangle_xi"] = dict(big["xi"])
    else:
        out["largest_tangle_share"] = 0.0
        out["largest_tangle_extent"] = {ax: 0.0 for ax in AXES}
        out["largest_tangle_xi"] = {ax: 0.0 for ax in AXES}
    axes = {ax for t in tangles for ax in t["percolates_axes"]}
    out["percolating_axes"] = [ax for ax in AXES if ax in axes]
    out["percolates"] = bool(axes)
    out["tangles"] = tangles[:_MAX_TANGLES_REPORTED]
    out["tangles_truncated"] = len(tangles) > _MAX_TANGLES_REPORTED

    hists = {}
    for name in hist_names:
        v = samples[name]
        if v.size == 0:
            hists[name] = None
            continue
        hk = histogram(v, bins=bins)
        hists[name] = {"edges": hk["edges"], "counts": hk["counts"], "density": hk["density"], "n": hk["n"]}
    out["histograms"] = hists
    # Fig. 4E-F: the tails of p(e) and p(c)
    out["power_law"] = {name: power_law_fit(samples[name]) if power_laws and name in samples else None
                        for name in ("e", "c")}
    out["z_profiles"] = z_profiles(fields)
    out["largest_contact_cluster_fraction"] = (None if contact_cluster_fraction is None
                                               else float(contact_cluster_fraction))
    return json_safe(out)
