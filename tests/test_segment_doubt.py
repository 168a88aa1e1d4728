"""Where the trace is unsure (rodwarp.ct.segment._doubt) and the curved-filament bridges
(rodwarp.ct.segment._bridging): known answers on phantoms, and the outputs that show them."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from rodwarp import ct
from rodwarp.ct import SegmentParams, segment_volume
from rodwarp.ct.segment._bridging import drop_duplicates, hermite, pair_ends
from rodwarp.ct.segment._doubt import DOUBT_CONFIDENCE, assess
from rodwarp.ct.segment._levels import _measure_levels
from rodwarp.ct.segment._reader import _Reader
from rodwarp.rodset import RodSet

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def packing():
    shape = (96, 96, 96)
    truth = ct.scene_random_packing(shape, n_rods=10, radius=3.0, aspect=8.0, seed=4, max_attempts=100000)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=8.0, seed=4)
    res = segment_volume(vol)
    P = SegmentParams()
    st = _measure_levels(_Reader(vol), P)
    return truth, vol, res, st, P


def _subset(rods: RodSet, keep) -> RodSet:
    keep = list(keep)
    return RodSet.from_polylines([rods.rod(k) for k in keep], rods.radii[keep], units=rods.units)


# ----------------------------------------------------------------------------------------------
# confidence and unexplained foreground
# ----------------------------------------------------------------------------------------------

def test_a_complete_trace_explains_the_foreground_and_is_confident(packing):
    truth, vol, res, st, P = packing
    d = res.doubt
    assert res.rods.n_rods == truth.n_rods
    assert d.unexplained_fraction < 0.01
    assert np.all(d.confidence >= DOUBT_CONFIDENCE) and len(d.doubtful) == 0
    assert np.all(d.support >= 0.99)
    q = res.quality["unexplained"]
    assert q["traces"] == truth.n_rods and q["doubtful"] == 0 and q["fraction"] == pytest.approx(d.unexplained_fraction)


def test_a_missed_rod_shows_as_an_unexplained_region_at_its_place(packing):
    truth, vol, res, st, P = packing
    k = 3
    rods = _subset(res.rods, [i for i in range(res.rods.n_rods) if i != k])
    d = assess(_Reader(vol), st, rods, P)
    missed = res.rods.rod(k)
    L = float(np.linalg.norm(missed[-1] - missed[0]))
    r = float(res.rods.radii[k])
    # the rod's binarised volume (a capsule) is unexplained now: its share of the foreground
    vol_rod = math.pi * r * r * L + 4.0 / 3.0 * math.pi * r ** 3
    assert d.unexplained_voxels == pytest.approx(vol_rod, rel=0.35)
    assert d.n_regions >= 1
    centre = np.asarray(d.regions[0]["centre"])
    assert np.linalg.norm(centre - missed.mean(0)) < r + 2.0


def test_a_trace_cut_short_has_an_open_end_and_less_confidence(packing):
    truth, vol, res, st, P = packing
    rods = res.rods.copy()
    k = 5
    p = rods.rod(k)
    # keep the first half: the rod goes on past the new end, no trace explains it
    i0 = rods.offsets[k]
    rods.points[i0 + len(p) - 1] = p[0] + 0.5 * (p[-1] - p[0])
    d = assess(_Reader(vol), st, rods, P)
    assert d.open_ends[k] == 1
    assert d.confidence[k] == pytest.approx(0.75 * d.support[k] * (1 - d.crowding[k]))
    assert np.delete(d.open_ends, k).max() == 0


def test_a_trace_off_its_rod_is_doubtful_with_its_reason(packing):
    truth, vol, res, st, P = packing
    rods = res.rods.copy()
    k = 2
    p = rods.rod(k)
    u = (p[-1] - p[0]) / np.linalg.norm(p[-1] - p[0])
    n = np.cross(u, [0.0, 0.0, 1.0] if abs(u[2]) < 0.9 else [1.0, 0.0, 0.0])
    n /= np.linalg.norm(n)
    i0 = rods.offsets[k]
    rods.points[i0:i0 + len(p)] += 3.0 * rods.radii[k] * n  # beside the rod, in the background
    d = assess(_Reader(vol), st, rods, P)
    assert d.support[k] < 0.5
    assert d.confidence[k] < DOUBT_CONFIDENCE and k in d.doubtful
    assert any("off the foreground" in w for w in d.doubts[k])
    assert d.unexplained_fraction > 0.05  # the rod it left is unexplained now


# ----------------------------------------------------------------------------------------------
# bridges
# ----------------------------------------------------------------------------------------------

def test_hermite_straight_and_quarter_turn():
    pts, rmin, energy = hermite([0, 0, 0], [1, 0, 0], [10, 0, 0], [1, 0, 0], 41)
    assert energy == pytest.approx(0.0, abs=1e-9) and rmin > 1e6
    assert np.allclose(pts[:, 1:], 0.0) and pts[0, 0] == 0.0 and pts[-1, 0] == pytest.approx(10.0)
    # a quarter turn over a chord of 10: an arc would have radius 7.07; the cubic bends harder
    pts, rmin, energy = hermite([0, 0, 0], [1, 0, 0], [5, 5, 0], [0, 1, 0], 201)
    assert 2.0 < rmin < 7.07
    assert energy > (math.pi / 2) ** 2 * math.sqrt(50) / (7.07 * math.pi / 2) * 0.9  # >= the arc's


def _disc_sampler(polys, r):
    """Normalised intensity 1 within r of the given polylines, 0 elsewhere (a binary scan)."""
    from scipy.spatial import cKDTree

    from rodwarp.ct.segment._score import resample_polyline

    tree = cKDTree(np.concatenate([resample_polyline(p, 0.25) for p in polys]))

    def f(q):
        d, _ = tree.query(np.asarray(q, float).reshape(-1, 3))
        return (d <= r).astype(float).reshape(np.shape(q)[:-1])

    def dist(q):
        d, _ = tree.query(np.asarray(q, float).reshape(-1, 3))
        return np.maximum(d - r, 0.0).reshape(np.shape(q)[:-1])
    return f, dist


def test_bridges_join_a_broken_curve_through_a_crossing_wire():
    # an arc of radius 40 (a wire bending about 16 radii) broken where another wire crosses it
    # on top (touching): the skeleton's junction gap, 12 voxels long
    r0 = 2.5
    th = np.radians(np.arange(10.0, 300.0, 1.0))
    arc = np.stack([40 * np.cos(th), 40 * np.sin(th), np.zeros_like(th)], 1)
    a, b = arc[:160], arc[177:]
    g = math.radians(178.5)
    s = np.linspace(20.0, 60.0, 41)
    c = np.stack([s * math.cos(g), s * math.sin(g), np.full_like(s, 2 * r0)], 1)
    sampler, dist = _disc_sampler([arc, c], r0)
    out, n = pair_ends([a, b, c], sampler, r0, 8 * r0 + 6)
    assert n == 1 and len(out) == 2
    merged = max(out, key=len)
    assert float(np.linalg.norm(np.diff(merged, axis=0), axis=1).sum()) == pytest.approx(40 * math.radians(289),
                                                                                       abs=2 * r0 + 1)
    # the bridge follows the arc through the crossing: every point within a radius of it
    assert np.abs(np.linalg.norm(merged[:, :2], axis=1) - 40.0).max() < r0
    assert np.abs(merged[:, 2]).max() < r0
    assert any(p.shape == c.shape and np.allclose(p, c) for p in out)  # the crossing wire is left alone
    # without the broken wire's foreground in the gap, no bridge
    sampler2, dist2 = _disc_sampler([a, b, c], r0)
    out2, n2 = pair_ends([a, b, c], sampler2, r0, 8 * r0 + 6)
    assert n2 == 0 and len(out2) == 3


def test_pairing_at_a_shallow_crossing_goes_straight_through():
    # two straight wires crossing at 35 degrees, one on top of the other (touching), each cut
    # into two pieces by the junction gap: four ends in one blob, three ways to pair them; the
    # straight-through pairing turns least (the swapped one turns 35 degrees twice)
    r0 = 2.5
    half = math.radians(17.5)
    s = np.arange(-60.0, 61.0, 1.0)
    u = np.stack([s * math.cos(half), s * math.sin(half), np.zeros_like(s)], 1)
    v = np.stack([s * math.cos(half), -s * math.sin(half), np.full_like(s, 2 * r0)], 1)
    sampler, _ = _disc_sampler([u, v], r0)
    cut = np.abs(s) > 7
    pieces = [u[cut & (s < 0)], u[cut & (s > 0)], v[cut & (s < 0)], v[cut & (s > 0)]]
    out, n = pair_ends(pieces, sampler, r0, 8 * r0 + 6)
    assert n == 2 and len(out) == 2
    for f in out:
        # each filament is one of the two wires: all of it within half a radius of that line
        on_u = np.linalg.norm(f - (f @ [math.cos(half), math.sin(half), 0])[:, None] *
                              np.array([math.cos(half), math.sin(half), 0]), axis=1)
        on_v = np.linalg.norm((f - [0, 0, 2 * r0]) - (f @ [math.cos(half), -math.sin(half), 0])[:, None] *
                              np.array([math.cos(half), -math.sin(half), 0]), axis=1)
        assert min(on_u.max(), on_v.max()) < 0.5 * r0
        assert float(np.linalg.norm(f[-1] - f[0])) > 110


def test_ends_are_fitted_with_the_bend():
    # the end tangent of a circle of radius 15 (6 radii: the tightest bend of the wire tangles)
    # from a quadratic fit is the circle's tangent; a chord over the same stretch lags by half
    # the turn (here 14 degrees)
    from rodwarp.ct.segment._bridging import _ends

    th = np.arange(0.0, 2.0, 1.0 / 15.0)
    p = np.stack([15 * np.cos(th), 15 * np.sin(th), np.zeros_like(th)], 1)
    (e0, t0, s0), (e1, t1, s1) = _ends([p], 2.5, 7.5)
    # the last end, 2.5 voxels in: angle 2 - 2.5/15 rad, outward tangent along +theta
    a = th[-1] - 2.5 / 15
    assert np.allclose(e1, [15 * math.cos(a), 15 * math.sin(a), 0], atol=0.05)
    assert math.degrees(math.acos(float(t1 @ [-math.sin(a), math.cos(a), 0]))) < 1.0
    assert s1 == pytest.approx(15 * th[-1] - 2.5, abs=0.05)


def test_duplicates_along_a_longer_filament_are_dropped():
    x = np.linspace(0, 80, 81)
    long = np.stack([x, np.zeros_like(x), np.zeros_like(x)], 1)
    dup = long[20:50] + [0.0, 1.5, 0.0]       # within 1.2 r of it (r = 2.5)
    beside = long[20:50] + [0.0, 5.0, 0.0]    # a touching neighbour, 2 r away
    kept, n = drop_duplicates([long, dup, beside], 2.5)
    assert n == 1 and len(kept) == 2
    assert [len(k) for k in kept] == [81, 30] and np.allclose(kept[1], beside)


# ----------------------------------------------------------------------------------------------
# the outputs, on a real scan
# ----------------------------------------------------------------------------------------------

def test_real_scan_outputs_confidence_and_unexplained(tmp_path):
    from rodwarp.ct import run_segment

    src = ROOT / "examples" / "data" / "pcl_scaffold_128.tif"
    out = tmp_path / "seg"
    summ = run_segment(src, voxel_size=1.0, units="voxel", out=out, params=SegmentParams(shape="curved"))
    for name in ("filaments.csv", "qa_confidence.png", "summary.json"):
        assert (out / name).exists()
    with open(out / "filaments.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == summ["n_rods"] > 100
    conf = np.array([float(r["confidence"]) for r in rows])
    assert np.all((conf >= 0) & (conf <= 1))
    doubtful = [r for r in rows if float(r["confidence"]) < DOUBT_CONFIDENCE]
    assert doubtful and all(r["doubts"] for r in doubtful)
    s = json.loads((out / "summary.json").read_text())
    assert s["quality"]["unexplained"]["doubtful"] == len(doubtful)
    assert 0.0 < s["quality"]["unexplained"]["fraction"] < 0.2
    assert [f["confidence"] for f in s["filaments"]] == pytest.approx(conf.tolist(), abs=1e-3)
    assert "filaments.csv" in s["files"] and "qa_confidence.png" in s["files"]
