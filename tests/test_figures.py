"""The figures show what the numbers say (issue 29, class 8).

Each test builds a figure from known data and reads its artists back: labels and units on
every axis, no power-law line the statistics rejected, no empty tangle panel, snapshot views
that one far rod does not stretch, and the test-start marker at ``test_start`` itself.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg

from rodwarp.analysis import Fields, field_statistics, find_tangles


def _fields(e: np.ndarray, c: np.ndarray | None = None, spacing: float = 0.05) -> Fields:
    nz, ny, nx = e.shape
    n = np.where(np.isfinite(e), 1.0, np.nan)
    c = 0.5 * e if c is None else c
    return Fields(phi=0.1 * np.ones_like(e), S=0.5 * np.ones_like(e), c=c, e=e, n=n,
                  x=np.arange(nx) * spacing, y=np.arange(ny) * spacing, z=np.arange(nz) * spacing,
                  radius=2 * spacing, spacing=spacing, units="m")


def _fit(accepted: bool, note: str = "") -> dict:
    return {"gamma": 1.5, "gamma_err": 0.1, "xmin": 0.5, "xmax": 20.0, "decades": 1.6, "n_range": 500,
            "range_fraction": 0.5, "ks": 0.03, "accepted": accepted, "note": note}


def _solid_lines(ax) -> list:
    """Lines drawn as lines (the fit), not the histogram's markers."""
    return [ln for ln in ax.get_lines() if ln.get_linestyle() not in ("None", "", " ")]


def test_distributions_label_every_axis_and_draw_only_accepted_fits():
    from rodwarp.analysis._figures import distributions_figure

    rng = np.random.default_rng(0)
    e = rng.pareto(1.5, size=(12, 10, 10)) + 0.1
    c = rng.lognormal(0.0, 0.5, size=e.shape)
    stats = {"power_law": {"e": _fit(True), "c": _fit(False, "no range passes the KS test: not a power law")}}
    fig = distributions_figure(_fields(e, c), stats)
    ax_e, ax_c = fig.axes
    for ax, sym in ((ax_e, "e"), (ax_c, "c")):
        # quantity and unit on both axes (the fields are dimensionless, which the label says)
        assert f"${sym}$" in ax.get_xlabel() and "[dimensionless]" in ax.get_xlabel()
        assert ax.get_ylabel().startswith("probability density") and f"per unit ${sym}$" in ax.get_ylabel()
    # the accepted fit of p(e) is drawn, the rejected one of p(c) is not: the panel says why
    assert len(_solid_lines(ax_e)) == 1
    assert _solid_lines(ax_c) == []
    notes = " ".join(t.get_text() for t in ax_c.texts)
    assert "rejected" in notes and "KS test" in notes
    assert not any("gamma" in t.get_text() for t in ax_c.get_legend().get_texts())
    # the x labels lie inside the rendered image (the old margins cut them off)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for ax in (ax_e, ax_c):
        box = ax.xaxis.label.get_window_extent(renderer)
        assert box.y0 >= 0 and box.x0 >= 0 and box.x1 <= fig.bbox.width


def test_tangle_panels_are_never_empty():
    from rodwarp.analysis._figures import tangles_figure

    # a tall packing whose only tangle sits low (as in a shaken pile): planes through the
    # middle of the packing missed it and left the xy label panel empty
    rng = np.random.default_rng(1)
    e = 1.0 + 0.1 * rng.random((40, 10, 10))
    e[3:6, 4:7, 2:5] = 100.0
    f = _fields(e)
    stats = field_statistics(f, power_laws=False)
    labels, _ = find_tangles(f.e, f.valid, stats["e_lb"], spacing=f.spacing, system_size=f.system_size)
    assert labels.max() == 1
    fig = tangles_figure(f, labels, stats)
    panels = [ax for ax in fig.axes if ax.get_title()]  # the six panels (colour bars carry no title)
    assert len(panels) == 6
    for ax in panels:
        shown = [np.ma.count(np.ma.masked_invalid(im.get_array())) for im in ax.get_images()]
        assert shown and max(shown) > 0, f"empty panel: {ax.get_title()}"
        if "tangles" in ax.get_title():
            # the label layer (the second image) holds tangle voxels in every label panel
            assert len(ax.get_images()) == 2, ax.get_title()
            assert np.ma.count(ax.get_images()[1].get_array()) > 0, ax.get_title()
    # the slice planes go through the tangle: z of the xy plane within its layers
    xy_title = next(ax.get_title() for ax in panels if ax.get_title().startswith("tangles, xy plane"))
    z_plane = float(xy_title.split("z = ")[1].split()[0])
    assert f.z[3] - 1e-9 <= z_plane <= f.z[5] + 1e-9


def _rods(n: int, n_vertices: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``n`` short straight rods inside the unit box with z up to 1; (points, offsets)."""
    offsets = np.arange(n + 1) * n_vertices
    a = rng.random((n, 3)) * [0.8, 0.8, 0.8] + 0.1
    d = rng.normal(size=(n, 3))
    d *= 0.05 / np.linalg.norm(d, axis=1, keepdims=True)
    s = np.linspace(0.0, 1.0, n_vertices)
    pts = (a[:, None, :] + s[None, :, None] * d[:, None, :]).reshape(-1, 3)
    return pts, offsets


def test_snapshot_view_is_not_stretched_by_one_far_rod():
    from rodwarp.rodset.trajectory import snapshot_view, snapshots_figure

    rng = np.random.default_rng(2)
    pts, offsets = _rods(300, 4, rng)
    thrown = pts.copy()
    thrown[offsets[7]:offsets[8], 2] += 10.0  # one rod thrown ten boxes high
    box = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    frames = [("start", pts), ("end", thrown)]
    view = snapshot_view(frames, offsets, box)
    zlo, zhi = view["z"]
    assert zlo <= 0.0 and 1.0 <= zhi < 1.5  # the box and the rods, not the thrown rod at z > 10
    assert view["above"] == [0, 1]
    assert abs(view["above_x"][1] - thrown[offsets[7]:offsets[8], 0].mean()) < 1e-12
    fig = snapshots_figure(frames, offsets, box)
    for ax in fig.axes:
        assert ax.get_ylim() == (zlo, zhi)
    # the far rod is counted, with an arrow, on the panel where it is out of view
    notes = [t.get_text() for t in fig.axes[1].texts]
    assert "1 rod above the view" in notes
    assert not fig.axes[0].texts


def test_metrics_marks_the_test_start_exactly():
    from rodwarp.experiments._recorder import plot_metrics

    save = 0.1
    t_start = 0.5
    rows = []
    for k in range(11):
        t = round(k * save, 10)
        stage = "entangle" if t <= t_start else "stability"
        test = stage == "stability"
        rows.append({"time": t, "stage": stage, "contacts_per_rod": 2.0 + t, "largest_cluster_fraction": 0.9,
                     "centroid_height": 1.0, "centroid_height_ratio": 1.0 - 0.1 * t,
                     "height_kept": 0.9 if test else "", "rods_left": 0.0 if test else "",
                     "kinetic_energy": 1e-3, "cv_e": "", "mean_e": ""})
    summary = {"thresholds": {"cluster": 0.8, "height_kept": 0.26}, "test_start": {"time": t_start},
               "alpha": 50.0, "a_over_g": 2.0, "stable": True, "height_kept": 0.9,
               "largest_cluster_fraction": 0.9, "persistence": 1.0}
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        fig = plot_metrics(Path(d) / "metrics.png", rows, summary)
    for ax in fig.axes:
        # the dashed marker: a vertical line (equal x at both ends) at test_start, not 0.6
        marks = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
        assert len(marks) == 1
        assert np.allclose(marks[0].get_xdata(), t_start)
    label = next(t for t in fig.axes[0].texts if t.get_text() == "stability test")
    assert label.xy[0] == t_start
