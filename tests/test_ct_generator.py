"""The second CT phantom generator (rodwarp.testing.ct_generator) against known answers: the
cut-cube volume, a capsule's partial volume summing to its volume, the scenes' true contacts at
exactly 2 r with every other pair clear, Poisson noise of the stated variance, and no code
shared with rodwarp.ct."""

from __future__ import annotations

import ast
import inspect
import math

import numpy as np
import pytest

from rodwarp.testing import ct_generator as g


def test_the_cut_cube_volume_is_exact():
    # special cases: a plane through the centre halves the cube whatever its normal
    for n in ([1, 0, 0], [1, 1, 0], [1, 1, 1], [0.2, -0.5, 0.9]):
        n = np.asarray(n, float) / np.linalg.norm(n)
        assert float(g.cube_fraction(np.array(0.0), n)) == pytest.approx(0.5, abs=1e-12)
    assert float(g.cube_fraction(np.array(0.5), np.array([1.0, 0, 0]))) == 1.0
    assert float(g.cube_fraction(np.array(-0.5), np.array([1.0, 0, 0]))) == 0.0
    # a corner cut by the diagonal plane: x + y + z <= -1.5 + t along (1,1,1)/sqrt(3) is t^3/6
    n = np.ones(3) / math.sqrt(3)
    t = 0.6
    assert float(g.cube_fraction(np.array(-1.5 / math.sqrt(3) + t / math.sqrt(3)), n)) == pytest.approx(t**3 / 6)
    # random planes against a fine Monte Carlo count (standard error 8e-4)
    rng = np.random.default_rng(5)
    pts = rng.uniform(-0.5, 0.5, (400_000, 3))
    for _ in range(12):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        d = rng.uniform(-0.9, 0.9)
        assert float(g.cube_fraction(np.array(d), n)) == pytest.approx(float(np.mean(pts @ n <= d)), abs=3e-3)


@pytest.mark.parametrize("r", [1.5, 2.0, 3.0])
def test_a_capsules_partial_volume_sums_to_its_volume(r):
    rng = np.random.default_rng(int(10 * r))
    for _ in range(3):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        c = np.array([32.3, 31.7, 32.1]) + rng.uniform(-0.5, 0.5, 3)
        L = 30.0
        scene = g.GeneratedScene((64, 64, 64), (c - L / 2 * u)[None], (c + L / 2 * u)[None], np.array([r]),
                                 np.array([0]), [], [])
        occ = g.occupancy(scene)
        assert occ.min() >= 0 and occ.max() == 1.0
        assert occ.sum() == pytest.approx(g.capsule_volume(r, L), rel=5e-3)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("r", [1.5, 2.0, 3.0])
def test_touching_bundles_state_their_contacts_exactly(seed, r):
    s = g.touching_bundles(shape=(80, 112, 112), radius=r, length=60.0, seed=seed)
    assert s.meta["n_bundles"] >= 3 and s.meta["n_crossing"] >= 1
    pairs = set(s.contacts)
    for i in range(s.n_rods):
        u = s.p1[i] - s.p0[i]
        assert abs(u[2]) / np.linalg.norm(u) <= math.sin(math.radians(25.0)) + 1e-12  # within 25 deg of horizontal
        for j in range(i + 1, s.n_rods):
            d = g._segment_distance(s.p0[i], s.p1[i], s.p0[j], s.p1[j])
            if (i, j) in pairs:
                assert d == pytest.approx(2 * r, abs=1e-6)  # touching with zero gap
            else:
                assert d >= 2 * r + 1.0 - 1e-9  # clear by a voxel at least
    hi = np.array(s.shape[::-1]) - 1
    assert np.all(np.minimum(s.p0, s.p1) >= r) and np.all(np.maximum(s.p0, s.p1) <= hi - r)


def test_wires_stay_apart_and_inside():
    s = g.wire_tangle(radius=2.0, seed=4)
    assert s.n_rods >= 6 and not s.contacts
    for a in range(s.n_rods):
        for b in range(a + 1, s.n_rods):
            D = np.linalg.norm(s.polylines[a][:, None] - s.polylines[b][None], axis=-1)
            assert D.min() >= 2 * 2.0 + 1.0
    assert len(s.p0) == sum(len(p) - 1 for p in s.polylines)


def test_the_noise_is_poisson_and_the_psf_keeps_the_mean():
    k = g.psf_kernel(0.8, 0.08)
    assert k.sum() == pytest.approx(1.0, abs=1e-12) and k.min() >= 0
    empty = g.GeneratedScene((40, 48, 48), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, int), [], [])
    for counts in (100.0, 400.0):
        v = g.render(empty, background=0.2, counts=counts, hardening=0.0, rings=0.0, seed=1) / 65535.0
        core = v[8:-8, 8:-8, 8:-8]
        assert core.mean() == pytest.approx(0.2, rel=0.01)
        assert core.var() == pytest.approx(0.2 / counts, rel=0.08)  # Poisson: variance = mean / counts


def test_the_same_seed_renders_the_same_volume():
    s = g.touching_bundles(shape=(48, 64, 64), radius=1.5, length=30.0, n_bundles=3, n_crossing=2, seed=7)
    a, b = g.render(s, seed=7), g.render(s, seed=7)
    assert a.dtype == np.uint16 and np.array_equal(a, b)
    assert not np.array_equal(a, g.render(s, seed=8))


def test_it_shares_no_code_with_rodwarp_ct():
    tree = ast.parse(inspect.getsource(g))
    names = [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    names += [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    assert not [m for m in names if m.startswith("rodwarp")]


def test_the_segment_distance_agrees_with_the_edge_search():
    rng = np.random.default_rng(3)
    P0, P1, Q0, Q1 = (rng.uniform(-5, 5, (20, 3)) for _ in range(4))
    P1[:3] = P0[:3] + [1.0, 0.0, 0.0]  # parallel pairs too
    Q1[:3] = Q0[:3] + [2.0, 0.0, 0.0]
    D, _, _ = g._closest_segments(P0, P1, Q0, Q1)
    for i in range(20):
        for j in range(20):
            assert D[i, j] == pytest.approx(g._segment_distance(P0[i], P1[i], Q0[j], Q1[j]), abs=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("r", [1.5, 2.0, 3.0])
def test_touching_wires_touch_at_zero_gap_and_the_rest_stay_clear(seed, r):
    s = g.wire_tangle(radius=r, seed=seed, touching=True)
    assert s.n_rods == 8 and s.meta["touching"]
    pairs = set(s.contacts)
    assert len(pairs) == len(s.contacts) >= 4  # most wires touch one they cross
    assert all(i < j for i, j in pairs)
    for i in range(s.n_rods):
        for j in range(i + 1, s.n_rods):
            d = g.polyline_distance(s.polylines[i], s.polylines[j])
            if (i, j) in pairs:
                assert d == pytest.approx(2 * r, abs=1e-6)  # touching: gap 0
            else:
                assert d >= 2 * r + 1.0  # clear by a voxel at least
    hi = np.array(s.shape[::-1]) - 1
    for p in s.polylines:
        assert np.all(p >= r) and np.all(p <= hi - r)
    assert len(s.p0) == sum(len(p) - 1 for p in s.polylines)
    assert np.all(s.radius == r)


def test_the_touching_option_leaves_the_apart_scenes_as_they_were():
    a = g.wire_tangle(radius=2.0, seed=4)
    b = g.wire_tangle(radius=2.0, seed=4, touching=False)
    assert not a.contacts and all(np.array_equal(x, y) for x, y in zip(a.polylines, b.polylines))
    c = g.wire_tangle(radius=2.0, seed=4, touching=True)
    assert c.contacts and c.meta["n_contacts"] == len(c.contacts)
