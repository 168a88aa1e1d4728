"""Statistics stage: outlier bound, tangles, percolation, moments, profiles, figures.

Every check has an exact answer worked out by hand from the planted input.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from rodwarp.analysis import Fields, field_statistics, find_tangles, histogram, outlier_bound, z_profiles
from rodwarp.errors import RodwarpError

PAPER_CASE = [1, 2, 3, 4, 5, 6, 7, 8, 12, 20]


def make_fields(e, spacing=1.0, phi=None, nan_other=False):
    """Fields around an e array: n = 1 wherever e is finite (so valid == isfinite(e))."""
    e = np.asarray(e, dtype=np.float64)
    nz, ny, nx = e.shape
    n = np.where(np.isfinite(e), 1.0, np.nan)
    other = np.full(e.shape, np.nan) if nan_other else 0.5 * e
    return Fields(phi=other if phi is None else phi, S=other, c=other, e=e, n=n,
                  x=np.arange(nx) * spacing, y=np.arange(ny) * spacing, z=np.arange(nz) * spacing,
                  radius=2 * spacing, spacing=spacing, units="mm")


# ----------------------------------------------------------------------------------------------
# outlier bound
# ----------------------------------------------------------------------------------------------

def test_outlier_bound_q3_paper_case():
    b = outlier_bound(PAPER_CASE)
    assert b["q1"] == pytest.approx(3.25)
    assert b["q3"] == pytest.approx(7.75)
    assert b["iqr"] == pytest.approx(4.5)
    assert b["e_lb"] == pytest.approx(14.5)
    assert {v for v in PAPER_CASE if v > b["e_lb"]} == {20}


def test_outlier_bound_q1_text_variant():
    b = outlier_bound(PAPER_CASE, method="q1")
    assert b["e_lb"] == pytest.approx(3.25 + 1.5 * 4.5)  # 10.0
    assert {v for v in PAPER_CASE if v > b["e_lb"]} == {12, 20}


def test_outlier_bound_ignores_nan_and_rejects_bad_method():
    b = outlier_bound(np.array(PAPER_CASE + [np.nan, np.inf, np.nan], dtype=float).reshape(13, 1))
    assert b["e_lb"] == pytest.approx(14.5)
    with pytest.raises(RodwarpError, match="method"):
        outlier_bound(PAPER_CASE, method="q2")
    with pytest.raises(RodwarpError):
        outlier_bound([np.nan, np.nan])


# ----------------------------------------------------------------------------------------------
# tangles
# ----------------------------------------------------------------------------------------------

def two_blobs():
    """Background e = 1, two blobs of e = 100: A (z 2, y 3, x 4 voxels) and B (1 x 2 x 2).

    B comes first in scan order, so ranking by size has to relabel them.
    """
    e = np.ones((10, 12, 14))
    e[5:7, 1:4, 1:5] = 100.0  # A: 24 voxels
    e[1:2, 8:10, 9:11] = 100.0  # B: 4 voxels
    return e


def test_two_planted_blobs_exact_counts_shares_extents():
    e = two_blobs()
    valid = np.ones(e.shape, dtype=bool)
    labels, tangles = find_tangles(e, valid, e_lb=50.0, spacing=0.5)
    assert len(tangles) == 2  # the authors' loop skipped the last label and would find 1
    a, b = tangles
    n_valid = 10 * 12 * 14
    assert (a["label"], a["n_voxels"], b["label"], b["n_voxels"]) == (1, 24, 2, 4)
    assert a["share"] == pytest.approx(24 / n_valid)
    assert b["share"] == pytest.approx(4 / n_valid)
    # extents are reported (x, y, z) although arrays are (z, y, x)
    assert a["bbox"] == {"x": [1, 4], "y": [1, 3], "z": [5, 6]}
    assert b["bbox"] == {"x": [9, 10], "y": [8, 9], "z": [1, 1]}
    assert a["xi"] == pytest.approx({"x": 2.0, "y": 1.5, "z": 1.0})
    assert b["xi"] == pytest.approx({"x": 1.0, "y": 1.0, "z": 0.5})
    # default L: bounding box of the valid voxels, (span + 1) * spacing = (7, 6, 5)
    assert a["xi_over_L"] == pytest.approx({"x": 2.0 / 7, "y": 1.5 / 6, "z": 1.0 / 5})
    assert not a["percolates"] and not b["percolates"]
    # labels: 1 is the largest tangle, exactly blob A
    blob_a = np.zeros(e.shape, dtype=bool)
    blob_a[5:7, 1:4, 1:5] = True
    assert np.array_equal(labels == 1, blob_a)
    assert int((labels == 2).sum()) == 4 and int((labels > 0).sum()) == 28


def test_two_blobs_through_field_statistics():
    f = make_fields(two_blobs(), spacing=0.5)
    s = field_statistics(f)
    # background 1 everywhere: Q1 = Q3 = 1, IQR 0, so e_lb = 1 and both blobs are outliers
    assert s["e_lb"] == pytest.approx(1.0)
    assert s["n_tangles"] == 2
    assert s["n_valid_voxels"] == 1680
    assert s["outlier_fraction"] == pytest.approx(28 / 1680)
    assert s["largest_tangle_share"] == pytest.approx(24 / 1680)
    assert s["largest_tangle_extent"] == pytest.approx({"x": 2.0 / 7, "y": 1.5 / 6, "z": 1.0 / 5})
    assert s["percolates"] is False and s["percolating_axes"] == []
    assert s["largest_contact_cluster_fraction"] is None
    json.dumps(s, allow_nan=False)  # strict JSON: no NaN, no numpy types


def test_no_tangles_gives_zero_extent():
    s = field_statistics(make_fields(np.ones((3, 4, 5))), contact_cluster_fraction=0.75)
    assert s["n_tangles"] == 0 and s["outlier_fraction"] == 0.0
    assert s["largest_tangle_share"] == 0.0
    assert s["largest_tangle_extent"] == {"x": 0.0, "y": 0.0, "z": 0.0}
    assert s["largest_contact_cluster_fraction"] == 0.75


@pytest.mark.parametrize("second", [(2, 2, 2), (1, 2, 2)], ids=["corner", "edge"])
def test_diagonal_contact_26_vs_6(second):
    e = np.zeros((4, 4, 4))
    e[1, 1, 1] = 10.0
    e[second] = 10.0
    valid = np.ones(e.shape, dtype=bool)
    _, t26 = find_tangles(e, valid, 5.0, connectivity=26)
    _, t6 = find_tangles(e, valid, 5.0, connectivity=6)
    assert [t["n_voxels"] for t in t26] == [2]
    assert [t["n_voxels"] for t in t6] == [1, 1]


def test_slab_spanning_x_percolates_along_x_only():
    # grid padded with invalid (NaN) voxels; valid region z 1..6, y 1..7, x 2..8
    e = np.full((8, 9, 10), np.nan)
    e[1:7, 1:8, 2:9] = 0.0
    e[3:5, 3:5, 2:9] = 9.0  # slab through the whole valid region along x
    f = make_fields(e)
    labels, tangles = find_tangles(f.e, f.valid, 1.0)
    assert len(tangles) == 1
    t = tangles[0]
    assert t["percolates_axes"] == ["x"] and t["percolates"]
    assert t["n_voxels"] == 28 and t["share"] == pytest.approx(28 / (6 * 7 * 7))  # of valid voxels, not the grid
    assert t["xi_over_L"] == pytest.approx({"x": 1.0, "y": 2 / 7, "z": 2 / 6})
    assert t["touches"] == {"x-": True, "x+": True, "y-": False, "y+": False, "z-": False, "z+": False}
    s = field_statistics(f, method="q3")
    assert s["percolates"] is True and s["percolating_axes"] == ["x"]
    # one voxel short of the x+ face: no longer percolating
    e[3:5, 3:5, 8] = 0.0
    _, tangles = find_tangles(e, np.isfinite(e), 1.0)
    assert tangles[0]["percolates_axes"] == [] and tangles[0]["touches"]["x-"]


def test_nan_voxels_never_count():
    e = np.zeros((3, 3, 7))
    e[1, 1, :] = 10.0  # a line along x ...
    e[1, 1, 3] = np.nan  # ... cut by a NaN voxel
    valid = np.ones(e.shape, dtype=bool)  # even if a caller marks the NaN voxel valid
    _, tangles = find_tangles(e, valid, 5.0, connectivity=26)
    assert [t["n_voxels"] for t in tangles] == [3, 3]
    # an outlier value outside the valid mask does not count either
    valid[1, 1, 0] = False
    _, tangles = find_tangles(e, valid, 5.0)
    assert sorted(t["n_voxels"] for t in tangles) == [2, 3]
    # through Fields: the NaN voxel is not valid and not in the moments
    f = make_fields(e)
    s = field_statistics(f)
    assert s["n_valid_voxels"] == 3 * 3 * 7 - 1
    assert s["mean_e"] == pytest.approx(6 * 10.0 / 62)


def test_bad_connectivity():
    e = np.zeros((2, 2, 2))
    with pytest.raises(RodwarpError, match="connectivity"):
        find_tangles(e, np.ones(e.shape, bool), 1.0, connectivity=18)
    with pytest.raises(RodwarpError, match="connectivity"):
        field_statistics(make_fields(e), connectivity=4)


# ----------------------------------------------------------------------------------------------
# moments, histograms, profiles
# ----------------------------------------------------------------------------------------------

def test_cv_e_population_std_and_all_nan_fields():
    e = np.array([[[1.0, 2.0, np.nan], [3.0, 4.0, np.nan]]])
    f = make_fields(e, nan_other=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an all-NaN phi must not warn
        s = field_statistics(f)
    assert s["mean_e"] == pytest.approx(2.5)
    assert s["std_e"] == pytest.approx(math.sqrt(1.25))  # ddof = 0, not sqrt(5/3)
    assert s["cv_e"] == pytest.approx(math.sqrt(1.25) / 2.5)
    assert s["mean_phi"] is None and s["mean_S"] is None and s["mean_c"] is None
    assert s["histograms"]["phi"] is None and s["histograms"]["e"]["n"] == 4
    json.dumps(s, allow_nan=False)


def test_histogram_counts_and_density():
    h = histogram([0.0, 1.0, 2.0, 3.0, np.nan], bins=2)
    assert np.allclose(h["edges"], [0.0, 1.5, 3.0])
    assert h["counts"].tolist() == [2, 2]
    assert np.allclose(h["density"], [2 / (4 * 1.5)] * 2)


def test_z_profiles_linear_in_z():
    nz, ny, nx = 5, 3, 4
    z = np.arange(nz) * 0.5
    e = np.broadcast_to((2.0 * z + 1.0)[:, None, None], (nz, ny, nx)).copy()
    e[1, 0, 0] = np.nan  # a missing voxel does not bias its layer
    e[3] = np.nan  # a layer with no valid voxel
    prof = z_profiles(make_fields(e, spacing=0.5))
    assert np.allclose(prof["z"], z)
    expect = 2.0 * z + 1.0
    expect[3] = np.nan
    assert np.allclose(prof["e"], expect, equal_nan=True)
    assert np.allclose(prof["phi"], 0.5 * expect, equal_nan=True)
    assert np.allclose(prof["n"], np.where(np.isnan(expect), np.nan, 1.0), equal_nan=True)


# ----------------------------------------------------------------------------------------------
# figures
# ----------------------------------------------------------------------------------------------

def _check_pngs(tmp_path, paths):
    for p in paths:
        assert p.exists() and p.stat().st_size > 1000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # atomic writes leave no temporary files behind
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == sorted(p.name for p in paths)


def test_plots_write_png(tmp_path):
    from rodwarp.analysis import plot_histograms, plot_slices, plot_tangles, plot_zprofiles

    e = two_blobs()
    e[:, :, 0] = np.nan  # some voxels outside the domain
    f = make_fields(e, spacing=0.5)
    s = field_statistics(f)
    labels, _ = find_tangles(f.e, f.valid, s["e_lb"])
    _check_pngs(tmp_path, [
        plot_histograms(f, s, tmp_path / "hist.png"),
        plot_slices(f, tmp_path / "slices.png"),
        plot_zprofiles(s, tmp_path / "zprof.png"),
        plot_tangles(f, labels, s, tmp_path / "tangles.png"),
    ])


def test_plots_with_missing_fields_and_defaults(tmp_path):
    from rodwarp.analysis import plot_histograms, plot_slices, plot_tangles, plot_zprofiles

    f = make_fields(two_blobs(), spacing=0.5, nan_other=True)  # only e and n: "not available" panels
    _check_pngs(tmp_path, [
        plot_histograms(f, None, tmp_path / "hist.png"),
        plot_slices(f, tmp_path / "slices.png"),
        plot_zprofiles(f, tmp_path / "zprof.png"),
        plot_tangles(f, None, None, tmp_path / "sub" / "tangles.png"),  # labels and stats computed
    ])


def test_histogram_of_values_equal_but_for_rounding():
    # a field constant over the packing (S = 1 for parallel rods) differs only in the last bits:
    # NumPy refuses to cut such a range into 40 bins, which made `rodwarp analyze` of a
    # parallel bundle fail with an internal error
    from rodwarp.analysis._stats import histogram

    v = np.array([1.0, 1.0 + 2.2e-16, 1.0 + 4.4e-16, np.nan])
    h = histogram(v, 40)
    assert h["n"] == 3 and h["counts"].sum() == 3 and len(h["edges"]) == 41
    assert h["edges"][0] < 1.0 < h["edges"][-1] and h["edges"][-1] - h["edges"][0] < 1e-5
    assert np.nansum(h["density"] * np.diff(h["edges"])) == pytest.approx(1.0)
