"""Segmentation of synthetic CT (rodwarp.ct) into rods and contacts: the issue-5 targets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rodwarp import ct
from rodwarp.ct import SegmentParams, SegmentResult, match_rods, score_contacts, segment_volume
from rodwarp.errors import RodwarpError
from rodwarp.rodset import Contacts, RodSet


def _angle_deg(u, v):
    u = u / np.linalg.norm(u)
    v = v / np.linalg.norm(v)
    return math.degrees(math.acos(min(1.0, abs(float(u @ v)))))


def _ends(rods: RodSet, i: int):
    p = rods.rod(i)
    return p[0], p[-1]


def _endpoint_error(found: RodSet, i: int, truth: RodSet, j: int) -> float:
    a0, a1 = _ends(found, i)
    b0, b1 = _ends(truth, j)
    return min(max(np.linalg.norm(a0 - b0), np.linalg.norm(a1 - b1)),
               max(np.linalg.norm(a0 - b1), np.linalg.norm(a1 - b0)))


# ----------------------------------------------------------------------------------------------
# single rods and pairs
# ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1])
def test_isolated_rod_endpoints_angle_radius(seed):
    shape = (64, 80, 96)
    truth = ct.scene_isolated(shape, radius=3.0, seed=seed)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=10.0, seed=seed)
    res = segment_volume(vol)
    assert isinstance(res, SegmentResult)
    assert res.rods.units == "voxel" and res.rods.n_rods == 1
    assert _endpoint_error(res.rods, 0, truth, 0) <= 1.0
    a0, a1 = _ends(res.rods, 0)
    b0, b1 = _ends(truth, 0)
    assert _angle_deg(a1 - a0, b1 - b0) <= 0.5
    assert abs(res.rods.radii[0] - 3.0) <= 0.3
    assert abs(res.diameter - 6.0) <= 0.6
    assert len(res.contacts) == 0
    assert set(res.timings) >= {"stats", "detect", "merge", "refine", "contacts", "total"}
    assert 0.0 < res.quality["fit_residual"] < 1.0


@pytest.mark.parametrize("kind,angle,gap,seed,n_contacts", [
    ("crossing", 90.0, 0.0, None, 1),
    ("crossing", 30.0, 0.0, None, 1),
    ("crossing", 90.0, 0.0, 3, 1),
    ("crossing", 30.0, 0.0, 3, 1),
    ("parallel", None, 0.0, None, 1),
    ("parallel", None, 0.0, 3, 1),
    ("crossing", 90.0, 2.0, None, 0),
    ("crossing", 30.0, 2.0, 3, 0),
    ("parallel", None, 2.0, 3, 0),
])
def test_pairs_two_rods_and_their_contact(kind, angle, gap, seed, n_contacts):
    shape = (64, 96, 96)
    if kind == "crossing":
        truth = ct.scene_crossing_pair(shape, angle, radius=3.0, gap=gap, seed=seed)
    else:
        truth = ct.scene_parallel_pair(shape, radius=3.0, gap=gap, seed=seed)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=10.0, seed=7)
    res = segment_volume(vol)
    assert res.rods.n_rods == 2
    m = match_rods(res.rods, truth)
    assert m.f1 == 1.0
    assert np.all(m.mean_distance <= 0.5) and np.all(m.angle_deg <= 1.0)
    assert len(res.contacts) == n_contacts
    if n_contacts:
        assert (res.contacts.rod_i[0], res.contacts.rod_j[0]) == (0, 1)
        assert abs(res.contacts.gap[0]) < 1.0
        assert res.rods.contacts is res.contacts


# ----------------------------------------------------------------------------------------------
# random packing at CNR 5
# ----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def packing():
    shape = (208, 208, 208)
    truth = ct.scene_random_packing(shape, n_rods=100, radius=3.0, aspect=30.0, touching_fraction=0.5,
                                    seed=0, max_attempts=100000)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=0)
    return truth, vol


def test_random_packing_meets_targets(packing):
    truth, vol = packing
    assert truth.n_rods >= 100 and len(truth.contacts) >= 20
    res = segment_volume(vol)
    m = match_rods(res.rods, truth, max_mean_distance=2.0, max_angle_deg=5.0)
    assert m.f1 >= 0.95
    assert np.mean(m.mean_distance <= 1.0) * m.recall >= 0.95
    assert np.median(m.angle_deg) <= 1.0
    cs = score_contacts(res.contacts, truth, m)
    assert cs.f1 >= 0.9
    assert abs(res.diameter - 6.0) <= 0.3
    assert res.quality["foreground_explained"] > 0.95


def test_chunked_matches_unchunked_and_is_deterministic():
    shape = (144, 144, 144)
    truth = ct.scene_random_packing(shape, n_rods=40, radius=3.0, aspect=15.0, seed=5)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=5)
    whole = segment_volume(vol)
    chunked = segment_volume(vol, SegmentParams(chunk=64))
    assert whole.rods.n_rods == chunked.rods.n_rods == truth.n_rods
    m = match_rods(chunked.rods, whole.rods, max_mean_distance=0.5, max_angle_deg=1.0)
    assert len(m.pairs) == whole.rods.n_rods
    assert m.endpoint_error.max() <= 0.1
    assert np.abs(whole.rods.radii - chunked.rods.radii).max() <= 0.1
    assert len(whole.contacts) == len(chunked.contacts)
    again = segment_volume(vol)
    assert np.array_equal(again.rods.points, whole.rods.points)
    assert np.array_equal(again.rods.radii, whole.rods.radii)
    assert np.array_equal(again.contacts.point, whole.contacts.point)


class _LazyVolume:
    """An array-like that only supports .shape/.dtype and basic slicing (like a zarr array)."""

    def __init__(self, a):
        self._a = a
        self.shape = a.shape
        self.dtype = a.dtype
        self.reads = 0

    def __getitem__(self, idx):
        self.reads += 1
        return np.array(self._a[idx])


def test_lazy_array_like_input_gives_the_same_rods():
    shape = (64, 96, 96)
    truth = ct.scene_crossing_pair(shape, 60.0, radius=3.0, seed=2)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=8.0, seed=2)
    ref = segment_volume(vol)
    lazy = _LazyVolume(vol)
    res = segment_volume(lazy, SegmentParams(chunk=48))
    assert lazy.reads > 0
    assert res.rods.n_rods == 2 and len(res.contacts) == 1
    m = match_rods(res.rods, ref.rods, max_mean_distance=0.5, max_angle_deg=1.0)
    assert len(m.pairs) == 2 and m.endpoint_error.max() <= 0.1


def test_tiff_via_ctio_lazy(tmp_path):
    from rodwarp import ct

    shape = (48, 64, 80)
    truth = ct.scene_isolated(shape, radius=3.0, seed=4)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=10.0, seed=4)
    path = ct.write_tiff(tmp_path / "rod.tif", vol)
    res = segment_volume(ct.open_volume_lazy(path), SegmentParams(chunk=32))
    assert res.rods.n_rods == 1
    assert _endpoint_error(res.rods, 0, truth, 0) <= 1.0


def test_given_diameter_and_progress():
    shape = (64, 80, 96)
    truth = ct.scene_isolated(shape, radius=3.0, seed=3)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=10.0, seed=3)
    calls = []
    res = segment_volume(vol, SegmentParams(diameter=6.0), progress=lambda s, d, t: calls.append((s, d, t)))
    assert res.diameter == 6.0 and np.all(res.rods.radii == 3.0)
    stages = {c[0] for c in calls}
    assert {"stats", "detect", "refine", "contacts"} <= stages
    assert all(0 <= d <= t for _, d, t in calls)
    assert _endpoint_error(res.rods, 0, truth, 0) <= 1.0


def test_flat_end_model_puts_ends_further_out():
    shape = (64, 80, 96)
    truth = ct.scene_isolated(shape, radius=3.0, seed=0)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=10.0, seed=0)
    cap = segment_volume(vol)
    flat = segment_volume(vol, SegmentParams(end_model="flat"))
    # a capsule end's half level lies about r - sigma^2 / r beyond the cap centre; a flat face's at the face
    assert 1.5 < flat.rods.rod_lengths()[0] / 2 - cap.rods.rod_lengths()[0] / 2 < 3.0


# ----------------------------------------------------------------------------------------------
# bad input
# ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("vol,msg", [
    (np.zeros((10, 10)), "3-D"),
    (np.zeros((0, 5, 5)), "empty"),
    (np.full((20, 20, 20), 7, np.uint16), "constant"),
    (np.full((10, 10, 10), np.nan), "NaN"),
    (np.random.default_rng(0).normal(100.0, 10.0, (40, 40, 40)).astype(np.float32), "no rods found"),
    (np.pad(np.ones((8, 8, 8)), 12) * 1000.0, "no rods found"),
])
def test_bad_volumes_give_one_line_errors(vol, msg):
    with pytest.raises(RodwarpError) as e:
        segment_volume(vol)
    text = str(e.value)
    assert msg in text and "\n" not in text
    if msg == "no rods found":
        assert "--diameter" in text


@pytest.mark.parametrize("kw", [dict(diameter=-1.0), dict(smooth_sigma=-1.0), dict(end_model="round"),
                                dict(chunk=4), dict(refine_iterations=-1), dict(radius_range=(2.0, 1.0))])
def test_bad_params(kw):
    with pytest.raises(RodwarpError):
        segment_volume(np.zeros((8, 8, 8)), SegmentParams(**kw))


# ----------------------------------------------------------------------------------------------
# scoring helpers
# ----------------------------------------------------------------------------------------------

def _rods(segs, r=3.0, contacts=None):
    return RodSet.from_polylines([np.asarray(s, float) for s in segs], r, units="voxel", contacts=contacts)


def test_match_rods_one_to_one_and_thresholds():
    truth = _rods([[[0, 0, 0], [100, 0, 0]], [[0, 20, 0], [100, 20, 0]], [[0, 40, 0], [0, 40, 100]]])
    found = _rods([[[100.5, 0.5, 0], [0.2, 0.4, 0]],        # truth 0, reversed, ~0.5 off
                   [[0, 20, 1.5], [100, 20, 1.5]],          # truth 1, 1.5 off
                   [[0, 40, 0], [100, 40, 20]],             # wrong angle: no match
                   [[50, 0.2, 0], [60, 0.2, 0]]])           # a second piece of truth 0: unmatched
    m = match_rods(found, truth)
    assert m.mapping() == {0: 0, 1: 1}
    assert m.n_found == 4 and m.n_true == 3
    assert m.precision == 0.5 and m.recall == pytest.approx(2 / 3)
    assert m.f1 == pytest.approx(2 * 0.5 * (2 / 3) / (0.5 + 2 / 3))
    assert m.mean_distance[0] < 0.6 and m.mean_distance[1] == pytest.approx(1.5)
    assert m.endpoint_error[0] == pytest.approx(np.hypot(0.5, 0.5))
    assert match_rods(found, truth, max_mean_distance=1.0).mapping() == {0: 0}


def test_score_contacts_counts_and_ambiguous_pairs():
    # 0-1 touch (gap 0), 1-2 nearly touch (gap 0.5: ambiguous), 2-3 far apart
    truth = _rods([[[0, 0, 0], [100, 0, 0]], [[50, -50, 6], [50, 50, 6]], [[0, 0, 12.5], [100, 0, 12.5]],
                   [[0, 60, 0], [100, 60, 0]]])
    truth.contacts = Contacts([0], [1], [[50, 0, 3]], [0.0])
    found = truth.copy()
    m = match_rods(found, truth)
    both = Contacts([0, 1], [1, 2], [[50, 0, 3], [50, 0, 9.25]], [0.0, 0.5])
    cs = score_contacts(both, truth, m)
    assert (cs.tp, cs.fp, cs.fn, cs.ignored) == (1, 0, 0, 1) and cs.f1 == 1.0
    wrong = Contacts([2], [3], [[0, 30, 6]], [0.2])
    cs = score_contacts(wrong, truth, m)
    assert (cs.tp, cs.fp, cs.fn) == (0, 1, 1) and cs.f1 == 0.0
    assert score_contacts(Contacts.empty(), truth, m).recall == 0.0
