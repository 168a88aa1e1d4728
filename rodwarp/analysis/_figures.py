"""PNG figures of the mesoscopic fields and their statistics (matplotlib, Agg).

Every function draws on its own ``matplotlib.figure.Figure``, which renders PNG through the Agg
canvas without touching pyplot: no global state, no window, and an interactive session's
backend is left alone. It writes the PNG atomically (:func:`rodwarp.rodset.files.save_figure`),
so a reader never sees a torn image, and returns the path. Which fields get which panels, and
their labels, come from the field registry (:data:`rodwarp.analysis.FIELDS`). Panels of fields
that are all NaN (not provided by the source) say "not available".

Arrays are (z, y, x); the images are drawn with physical coordinates (voxel centres +- half a
spacing) in ``Fields.units``.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from rodwarp.analysis._registry import field_spec, fields_with
from rodwarp.analysis._stats import field_statistics, find_tangles, log_histogram, power_law_density, z_profiles
from rodwarp.rodset.files import save_figure

__all__ = ["plot_histograms", "plot_slices", "plot_zprofiles", "plot_tangles", "plot_distributions",
           "tangles_figure", "distributions_figure"]

#: fixed margins instead of constrained layout, which took most of each figure's time (the
#: main job's four figures: 2.7 s, 1.5 s of it in the layout solver; benchmarks/RESULTS.md)
_GRID = dict(left=0.08, right=0.97, bottom=0.08, top=0.92, wspace=0.25, hspace=0.32)


def _label(name: str) -> str:
    return field_spec(name).label


def _symbol(name: str) -> str:
    return field_spec(name).symbol


def _not_available(ax, what: str) -> None:
    ax.text(0.5, 0.5, f"{what}\nnot available", ha="center", va="center", transform=ax.transAxes, color="0.4")
    ax.set_xticks([])
    ax.set_yticks([])


def _units(fields) -> str:
    return getattr(fields, "units", "") or ""


def _extent(c0: np.ndarray, c1: np.ndarray, h: float) -> list[float]:
    """imshow extent so that pixels sit on voxel centres (each pixel one spacing wide)."""
    return [c0[0] - h / 2, c0[-1] + h / 2, c1[0] - h / 2, c1[-1] + h / 2]


def _mid_indices(fields) -> tuple[int, int, int]:
    """Middle (kz, jy, ix) of the valid voxels' bounding box (the grid's middle if none)."""
    v = fields.valid
    mids = []
    for axis, size in zip(range(3), v.shape):
        other = tuple(i for i in range(3) if i != axis)
        idx = np.flatnonzero(v.any(axis=other))
        mids.append(int((idx[0] + idx[-1]) // 2) if idx.size else size // 2)
    return tuple(mids)


def _mid_planes(fields):
    """Indices of the mid xy plane (kz) and mid xz plane (jy), the length unit, and the imshow
    extents of the two planes."""
    kz, jy, _ = _mid_indices(fields)
    h = float(fields.spacing)
    return kz, jy, _units(fields), _extent(fields.x, fields.y, h), _extent(fields.x, fields.z, h)


def _robust_range(a: np.ndarray) -> tuple[float, float] | None:
    """0.5 / 99.5 percentiles of the finite values: a long tail (e) should not wash out the map."""
    v = a[np.isfinite(a)]
    if v.size == 0:
        return None
    lo, hi = np.percentile(v, [0.5, 99.5])
    if hi <= lo:
        lo, hi = float(v.min()), float(v.max())
        if hi <= lo:
            lo, hi = lo - 0.5, hi + 0.5
    return float(lo), float(hi)


# ----------------------------------------------------------------------------------------------

def plot_histograms(fields, stats: dict | None, path) -> Path:
    """Distributions p(phi), p(S), p(c), p(e), ... with the mean dashed and e_lb on p(e).

    One panel per field with a histogram in the registry (two columns up to four fields,
    three beyond).

    Parameters
    ----------
    fields : rodwarp.analysis.Fields
        Used for the title (units, shape) and, when ``stats`` is None, to compute them.
    stats : dict or None
        Output of :func:`rodwarp.analysis.field_statistics` (its ``histograms``, means,
        ``e_lb``).
    path : path-like
        PNG to write.

    Returns
    -------
    pathlib.Path
    """
    if stats is None:
        stats = field_statistics(fields)
    specs = fields_with("histogram")
    ncols = 2 if len(specs) <= 4 else 3
    nrows = max(1, math.ceil(len(specs) / ncols))
    fig = Figure(figsize=(4.5 * ncols, 3.5 * nrows))
    axs = fig.subplots(nrows, ncols, squeeze=False, gridspec_kw=_GRID).ravel()
    for ax in axs[len(specs):]:
        ax.set_axis_off()
    for ax, spec in zip(axs, specs):
        name = spec.name
        h = stats.get("histograms", {}).get(name)
        if h is None:
            _not_available(ax, spec.label)
            continue
        edges = np.asarray(h["edges"], dtype=float)
        dens = np.asarray([np.nan if d is None else d for d in h["density"]], dtype=float)
        ax.stairs(np.nan_to_num(dens), edges, fill=True, alpha=0.35, color="C0")
        ax.stairs(np.nan_to_num(dens), edges, color="C0")
        mean = stats.get(spec.summary) if spec.summary else None
        if mean is not None:
            ax.axvline(mean, color="k", ls="--", lw=1, label=f"mean {mean:.3g}")
        if name == "e" and stats.get("e_lb") is not None:
            method = stats.get("outlier_method", "q3")
            rule = "Q3" if method == "q3" else "Q1"
            ax.axvline(stats["e_lb"], color="C3", lw=1.5,
                       label=rf"$e_{{lb}}$ = {rule} + 1.5 IQR = {stats['e_lb']:.3g}")
            ax.axvspan(stats["e_lb"], edges[-1], color="C3", alpha=0.08)
        ax.set_xlabel(spec.label)
        ax.set_ylabel(f"p({spec.symbol})")
        ax.legend(fontsize=8, loc="upper right")
    cv = stats.get("cv_e")
    title = f"field distributions ({stats.get('n_valid_voxels', '?')} valid voxels"
    title += f", $\\sigma_e/\\mu_e$ = {cv:.3g})" if cv is not None else ")"
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_slices(fields, path) -> Path:
    """Mid-plane slices of phi, S, c, e, n: xy plane at mid z and xz plane at mid y.

    Parameters
    ----------
    fields : rodwarp.analysis.Fields
        One row of panels per field with slices in the registry.
    path : path-like
        PNG to write.

    Returns
    -------
    pathlib.Path

    Notes
    -----
    "Mid" is the middle of the valid voxels' bounding box. Each row shares one colour scale and
    colourbar (0.5-99.5 percentiles of the whole field); NaN (outside the domain) is light grey.
    """
    kz, jy, u, ext_xy, ext_xz = _mid_planes(fields)
    y, z = fields.y, fields.z
    # keep panels to scale but not absurdly tall or flat
    names = [f.name for f in fields_with("slices")]
    fig = Figure(figsize=(10, 3.0 * len(names)))
    axs = fig.subplots(len(names), 2, squeeze=False,
                       gridspec_kw=dict(left=0.08, right=0.9, bottom=0.04, top=0.95, wspace=0.3, hspace=0.45))
    for row, name in enumerate(names):
        a = fields.get(name)
        rng = _robust_range(a[fields.valid]) if np.any(fields.valid) else None
        if rng is None:
            _not_available(axs[row, 0], _label(name))
            _not_available(axs[row, 1], _label(name))
            continue
        cmap = matplotlib.colormaps["viridis"].with_extremes(bad="0.85")
        for col, (img, ext, xl, yl, ttl) in enumerate((
                (a[kz], ext_xy, "x", "y", f"xy plane, z = {z[kz]:.4g} {u}"),
                (a[:, jy, :], ext_xz, "x", "z", f"xz plane, y = {y[jy]:.4g} {u}"))):
            ax = axs[row, col]
            im = ax.imshow(np.ma.masked_invalid(img), origin="lower", extent=ext, cmap=cmap,
                           vmin=rng[0], vmax=rng[1], interpolation="nearest", aspect="equal")
            ax.set_xlabel(f"{xl} [{u}]")
            ax.set_ylabel(f"{yl} [{u}]")
            ax.set_title(f"{_symbol(name)}: {ttl}", fontsize=9)
        # both planes share the row's scale, so one colourbar per row says it all
        fig.colorbar(im, ax=axs[row, :], shrink=0.85, extend="both", label=_symbol(name))
    fig.suptitle(f"mid-plane slices (grid {fields.shape[2]} x {fields.shape[1]} x {fields.shape[0]}, "
                 f"R = {fields.radius:.4g} {u}, spacing {float(fields.spacing):.4g} {u})")
    return save_figure(fig, path)


def plot_zprofiles(source, path) -> Path:
    """Horizontal means phi(z), S(z), c(z), e(z), n(z), ... against height.

    Parameters
    ----------
    source : Fields, dict
        Fields, the output of :func:`rodwarp.analysis.field_statistics` (its ``z_profiles``),
        or the output of :func:`rodwarp.analysis.z_profiles`; one panel per field with a
        z-profile in the registry.
    path : path-like
        PNG to write.

    Returns
    -------
    pathlib.Path
    """
    if isinstance(source, dict):
        prof = source.get("z_profiles", source)
        units = source.get("units", "")
    else:
        prof = z_profiles(source)
        units = _units(source)
    if "z" not in prof:
        raise ValueError("plot_zprofiles needs Fields, field_statistics output or z_profiles output")
    z = np.asarray(prof["z"], dtype=float)
    names = [f.name for f in fields_with("zprofile")]
    fig = Figure(figsize=(2.6 * len(names), 4.2))
    axs = fig.subplots(1, len(names), sharey=True, squeeze=False,
                       gridspec_kw=dict(left=0.07, right=0.98, bottom=0.16, top=0.88, wspace=0.12))[0]
    for ax, name in zip(axs, names):
        vals = prof.get(name)
        v = None if vals is None else np.asarray([np.nan if q is None else q for q in vals], dtype=float)
        if v is None or not np.any(np.isfinite(v)):
            _not_available(ax, _label(name))
            continue
        ax.plot(v, z, "o-", ms=3)
        ax.set_xlabel(_label(name))
        ax.grid(alpha=0.3)
    axs[0].set_ylabel(f"z [{units}]" if units else "z")
    fig.suptitle("horizontal averages against height")
    return save_figure(fig, path)


def _label_cmap(n: int) -> ListedColormap:
    """Colours for labels 1..n cycling tab20, with the largest tangle (label 1) always red."""
    base = list(matplotlib.colormaps["tab20"].colors)
    base = [c for i, c in enumerate(base) if i not in (6, 7)]  # tab20's reds, reserved for label 1
    colours = [(0.85, 0.1, 0.1)] + [base[i % len(base)] for i in range(max(n - 1, 0))]
    return ListedColormap(colours if colours else [(0.85, 0.1, 0.1)])


def _project_largest(labels: np.ndarray, axis: int) -> np.ndarray:
    """Projection of tangle labels along an axis, where the largest tangle present wins.

    Labels are ranked (1 = largest), so the smallest positive label along the line of sight is
    the largest tangle; a plain max would let small tangles hide the big one.
    """
    big = np.iinfo(np.int32).max
    proj = np.where(labels > 0, labels, big).min(axis=axis)
    return np.where(proj == big, 0, proj)


def _planes_through_largest(labels: np.ndarray, kz: int, jy: int) -> tuple[int, int]:
    """The xy plane (kz) and xz plane (jy) holding the most voxels of the largest tangle.

    Tangles sit where the entanglement is high, often low in a pile: planes through the middle
    of the packing missed them and left the slice panels of tangles.png empty.  Without any
    tangle the given (middle) planes are kept.
    """
    largest = np.asarray(labels) == 1
    if not largest.any():
        return kz, jy
    return int(np.argmax(largest.sum(axis=(1, 2)))), int(np.argmax(largest.sum(axis=(0, 2))))


def plot_tangles(fields, labels, stats: dict | None, path) -> Path:
    """Maps of the tangles: e with outliers outlined, tangle labels, and projections.

    Top row: e in the xy plane and the xz plane through the largest tangle (the planes holding
    most of its voxels; the middle planes when there is no tangle), outlier voxels (e > e_lb)
    outlined in red; then the tangle labels projected along y (xz view). Bottom row: tangle
    labels in the same two planes, then projected along z (xy view). The largest tangle is
    red in every label panel; in projections the largest tangle on a line of sight is shown.

    Parameters
    ----------
    fields : rodwarp.analysis.Fields
        The fields (only ``e`` is drawn).
    labels : ndarray of int, shape (nz, ny, nx), or None
        Tangle labels from :func:`rodwarp.analysis.find_tangles` (1 = largest); None to
        compute them from ``stats`` (its ``e_lb`` and ``connectivity``).
    stats : dict or None
        Output of :func:`rodwarp.analysis.field_statistics`, computed when None.
    path : path-like
        The PNG.

    Returns
    -------
    pathlib.Path
    """
    return save_figure(tangles_figure(fields, labels, stats), path)


def tangles_figure(fields, labels, stats: dict | None) -> Figure:
    """The figure of :func:`plot_tangles` (same arguments but the path), not yet written."""
    if stats is None:
        stats = field_statistics(fields)
    if labels is None:
        labels, _ = find_tangles(fields.e, fields.valid, stats["e_lb"], connectivity=stats.get("connectivity", 26),
                                 spacing=fields.spacing, system_size=fields.system_size)
    labels = np.asarray(labels)
    if labels.shape != fields.shape:
        raise ValueError(f"labels have shape {labels.shape}, the fields {fields.shape}")
    kz, jy, u, ext_xy, ext_xz = _mid_planes(fields)
    kz, jy = _planes_through_largest(labels, kz, jy)
    y, z = fields.y, fields.z
    n_lab = int(labels.max()) if labels.size else 0
    lcmap = _label_cmap(n_lab).with_extremes(bad=(1, 1, 1, 0))
    e_cmap = matplotlib.colormaps["Greys"].with_extremes(bad=(0.8, 0.87, 0.95))  # outside: pale blue

    fig = Figure(figsize=(15, 9))
    axs = fig.subplots(2, 3, gridspec_kw=dict(left=0.05, right=0.97, bottom=0.07, top=0.92, wspace=0.35, hspace=0.3))
    e = fields.e
    rng = _robust_range(e[fields.valid]) if np.any(fields.valid) else None
    outlier = labels > 0

    def draw_e(ax, img, mask, ext, xl, yl, title):
        if rng is None:
            _not_available(ax, _label("e"))
            return
        im = ax.imshow(np.ma.masked_invalid(img), origin="lower", extent=ext, cmap=e_cmap, vmin=rng[0],
                       vmax=rng[1], interpolation="nearest")
        if mask.any():
            ax.contour(mask.astype(float), levels=[0.5], colors="C3", linewidths=1.0, origin="lower", extent=ext)
        fig.colorbar(im, ax=ax, shrink=0.8, extend="both", label=_symbol("e"))
        ax.set(xlabel=f"{xl} [{u}]", ylabel=f"{yl} [{u}]")
        ax.set_title(title, fontsize=9)

    def draw_labels(ax, img, ext, xl, yl, title, domain):
        # the domain in light grey so empty panels still show where the packing is
        ax.imshow(np.where(domain, 0.12, np.nan), origin="lower", extent=ext, cmap="Greys", vmin=0, vmax=1,
                  interpolation="nearest")
        if n_lab:
            ax.imshow(np.ma.masked_less_equal(img, 0), origin="lower", extent=ext, cmap=lcmap, vmin=0.5,
                      vmax=n_lab + 0.5, interpolation="nearest")
        else:
            ax.text(0.5, 0.5, "no tangles", ha="center", va="center", transform=ax.transAxes)
        ax.set(xlabel=f"{xl} [{u}]", ylabel=f"{yl} [{u}]")
        ax.set_title(title, fontsize=9)

    valid = fields.valid
    draw_e(axs[0, 0], e[kz], outlier[kz], ext_xy, "x", "y", f"e, xy plane at z = {z[kz]:.4g} {u}; red: e > e_lb")
    draw_e(axs[0, 1], e[:, jy, :], outlier[:, jy, :], ext_xz, "x", "z",
           f"e, xz plane at y = {y[jy]:.4g} {u}; red: e > e_lb")
    draw_labels(axs[0, 2], _project_largest(labels, 1), ext_xz, "x", "z", "tangles projected along y",
                valid.any(axis=1))
    draw_labels(axs[1, 0], labels[kz], ext_xy, "x", "y", f"tangles, xy plane at z = {z[kz]:.4g} {u}", valid[kz])
    draw_labels(axs[1, 1], labels[:, jy, :], ext_xz, "x", "z", f"tangles, xz plane at y = {y[jy]:.4g} {u}",
                valid[:, jy, :])
    draw_labels(axs[1, 2], _project_largest(labels, 0), ext_xy, "x", "y", "tangles projected along z",
                valid.any(axis=0))

    from matplotlib.ticker import MaxNLocator

    for ax in axs.flat:  # a tall, narrow panel (the xz plane of a tall pile) crowds its x ticks
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        ax.xaxis.set_major_locator(MaxNLocator(2 if abs(x1 - x0) < 0.6 * abs(y1 - y0) else 4))
    ext = stats.get("largest_tangle_extent") or {}
    sub = (f"{stats.get('n_tangles', n_lab)} tangles (connectivity {stats.get('connectivity', 26)}), "
           f"e_lb = {stats.get('e_lb', float('nan')):.3g}, outliers {100 * stats.get('outlier_fraction', 0):.2f}% "
           f"of valid voxels; largest (red): "
           + ", ".join(f"xi_{a}/L_{a} = {ext.get(a, 0):.2f}" for a in "xyz")
           + ("; percolates along " + ",".join(stats["percolating_axes"]) if stats.get("percolates") else
              "; no tangle percolates"))
    fig.suptitle(sub, fontsize=10)
    return fig


def _unit_text(name: str) -> str:
    """The unit of field ``name`` for an axis label (the registry writes "1" for dimensionless)."""
    units = field_spec(name).units
    return "dimensionless" if units in ("1", "") else units


def distributions_figure(fields, stats: dict) -> Figure:
    """The figure of :func:`plot_distributions`, not yet written (tests read its artists).

    A fit the statistics mark as rejected (``accepted`` False: no range passes the KS test,
    or too short a range) is not drawn: a line over the points would read as a power law
    the analysis found none of.  The panel says why instead.
    """
    fig = Figure(figsize=(9.0, 3.8))
    # room below the axes for the x labels (the shared _GRID's 8 % cut them off at this height)
    axs = fig.subplots(1, 2, gridspec_kw=dict(_GRID, bottom=0.15, top=0.9))
    for ax, name in zip(axs, ("e", "c")):
        sym = _symbol(name)
        a = fields.get(name)
        h = log_histogram(a[fields.valid & np.isfinite(a)])
        if h is None:
            _not_available(ax, _label(name))
            continue
        ax.loglog(h["x"], h["density"], "o", ms=3, color="C0", label=f"p({sym})")
        fit = (stats.get("power_law") or {}).get(name)
        if fit and fit.get("accepted", True):
            x = np.geomspace(fit["xmin"], fit["xmax"], 20)
            ax.loglog(x, power_law_density(x, fit), "-", color="C3",
                      label=f"power law, gamma = {fit['gamma']:.2f} +- {fit['gamma_err']:.2f} "
                            f"over {fit['decades']:.2f} dec.")
        elif fit:
            why = fit.get("note") or "rejected"
            ax.text(0.03, 0.03, f"power-law fit rejected:\n{why}", transform=ax.transAxes, fontsize=7,
                    color="0.35", va="bottom", ha="left")
        ax.set_xlabel(f"{_label(name)} [{_unit_text(name)}]")
        ax.set_ylabel(f"probability density p({sym}) [per unit {sym}]")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3, which="major")
        ax.xaxis.set_minor_formatter(NullFormatter())
    fig.suptitle(f"distributions of the fields ({int(fields.valid.sum())} valid voxels)", fontsize=10)
    return fig


def plot_distributions(fields, stats: dict, path) -> Path:
    """p(e) and p(c) on log-log axes (the paper's Fig. 4E-F): log-binned densities of the valid
    voxels' values and the fitted power law (:func:`rodwarp.analysis.power_law_fit`) drawn
    over its range, with its exponent and the decades it spans, when the fit is accepted (a
    rejected fit is named with its reason, not drawn).

    Parameters
    ----------
    fields : rodwarp.analysis.Fields
        The fields (valid voxels only).
    stats : dict
        Output of :func:`rodwarp.analysis.field_statistics` (its ``power_law``).
    path : path-like
        PNG to write.

    Returns
    -------
    pathlib.Path
    """
    save_figure(distributions_figure(fields, stats), path)
    return Path(path)
