"""Warp segment-segment narrowphase against an independent NumPy reference and special cases."""

import math

import numpy as np
import pytest
import warp as wp
from scipy.optimize import minimize

from rodwarp import _warp
from rodwarp.kernels import narrowphase
from rodwarp.kernels.narrowphase import SegmentPair, capsule_gap, closest_points, closest_points_segments


# --------------------------------------------------------------------------------------------
# independent reference: exact minimum of the convex quadratic over the unit square, as the
# smallest distance among the interior stationary point and the four edge problems (each an
# exact point-segment problem).  Every candidate is a realised pair, so each is an upper bound.
# --------------------------------------------------------------------------------------------


def _dot(u, v):
    return np.einsum("...i,...i", u, v)


def _point_segment_t(x, a, b):
    d = b - a
    dd = _dot(d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(dd > 0, _dot(x - a, d) / np.where(dd > 0, dd, 1.0), 0.0)
    return np.clip(t, 0.0, 1.0)


def reference(p0, p1, q0, q1):
    """Exact (s, t, dist) by candidate enumeration, vectorised over the leading axis."""
    p0, p1, q0, q1 = (np.asarray(v, dtype=np.float64).reshape(-1, 3) for v in (p0, p1, q0, q1))
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    cands = []
    for s in (0.0, 1.0):  # edges s = 0, 1: point P(s) against segment Q
        ss = np.full(len(p0), s)
        cands.append((ss, _point_segment_t(p0 + s * d1, q0, q1)))
    for t in (0.0, 1.0):  # edges t = 0, 1: point Q(t) against segment P
        tt = np.full(len(p0), t)
        cands.append((_point_segment_t(q0 + t * d2, p0, p1), tt))
    a, b, e = _dot(d1, d1), _dot(d1, d2), _dot(d2, d2)
    c, f = _dot(d1, r), _dot(d2, r)
    det = a * e - b * b
    ok = det > 1e-10 * a * e
    with np.errstate(divide="ignore", invalid="ignore"):
        s_in = np.where(ok, (b * f - c * e) / np.where(ok, det, 1.0), 0.0)
        t_in = np.where(ok, (a * f - b * c) / np.where(ok, det, 1.0), 0.0)
    cands.append((np.clip(s_in, 0.0, 1.0), np.clip(t_in, 0.0, 1.0)))
    best = np.full(len(p0), np.inf)
    bs = np.zeros(len(p0))
    bt = np.zeros(len(p0))
    for s, t in cands:
        dist = np.linalg.norm(p0 + s[:, None] * d1 - q0 - t[:, None] * d2, axis=1)
        better = dist < best
        best = np.where(better, dist, best)
        bs = np.where(better, s, bs)
        bt = np.where(better, t, bt)
    return bs, bt, best


def grid_min(p0, p1, q0, q1, n=81):
    g = np.linspace(0.0, 1.0, n)
    P = p0 + g[:, None] * (p1 - p0)
    Q = q0 + g[:, None] * (q1 - q0)
    D = np.linalg.norm(P[:, None, :] - Q[None, :, :], axis=2)
    i, j = np.unravel_index(np.argmin(D), D.shape)
    return D[i, j], g[i], g[j]


def dense_min(p0, p1, q0, q1):
    """Grid search refined by bounded minimisation of the squared distance."""
    d0, s0, t0 = grid_min(p0, p1, q0, q1)

    def fun(x):
        v = p0 + x[0] * (p1 - p0) - q0 - x[1] * (q1 - q0)
        g = 2.0 * np.array([v @ (p1 - p0), -(v @ (q1 - q0))])
        return v @ v, g

    res = minimize(fun, [s0, t0], jac=True, bounds=[(0, 1), (0, 1)], method="L-BFGS-B",
                   options={"ftol": 1e-15, "gtol": 1e-12})
    return min(math.sqrt(max(res.fun, 0.0)), d0)


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------


def cp(p0, p1, q0, q1):
    """One pair through the Warp kernel, as scalars."""
    r = closest_points([p0], [p1], [q0], [q1])
    return {k: v[0] for k, v in r.items()}


def random_pairs(rng, n, spread=1.0):
    p0 = rng.uniform(-spread, spread, (n, 3))
    q0 = rng.uniform(-spread, spread, (n, 3))
    lp = 10.0 ** rng.uniform(-2, 0.5, n)
    lq = 10.0 ** rng.uniform(-2, 0.5, n)
    u = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    v /= np.linalg.norm(v, axis=1)[:, None]
    return p0, p0 + lp[:, None] * u, q0, q0 + lq[:, None] * v


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


@pytest.fixture(scope="module")
def rng():
    return np.random.default_rng(20240611)


@pytest.fixture(scope="module")
def generic(rng):
    p0, p1, q0, q1 = random_pairs(rng, 2500)
    return (p0, p1, q0, q1), closest_points(p0, p1, q0, q1)


def check_against_reference(pts, out, rtol=1e-9):
    p0, p1, q0, q1 = pts
    _, _, dref = reference(p0, p1, q0, q1)
    scale = np.max(np.abs(np.stack(pts)), axis=(0, 2))
    err = np.abs(out["dist"] - dref)
    assert np.all(err <= rtol * dref + 1e-14 * scale), np.max(err / np.maximum(dref, 1e-300))
    assert np.all((out["s"] >= 0) & (out["s"] <= 1) & (out["t"] >= 0) & (out["t"] <= 1))
    realised = np.linalg.norm(out["pa"] - out["pb"], axis=1)
    assert np.allclose(realised, out["dist"], rtol=1e-12, atol=1e-14 * np.max(scale))
    assert np.allclose(np.linalg.norm(out["normal"], axis=1), 1.0, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# random pairs
# --------------------------------------------------------------------------------------------


def test_reference_is_a_true_minimum(rng):
    """The enumeration reference never exceeds a grid + bounded-minimiser search."""
    p0, p1, q0, q1 = random_pairs(rng, 60)
    _, _, dref = reference(p0, p1, q0, q1)
    for i in range(len(p0)):
        dd = dense_min(p0[i], p1[i], q0[i], q1[i])
        assert dref[i] <= dd + 1e-12
        assert dd - dref[i] <= 1e-6 * max(1.0, dref[i])


def test_random_pairs_match_reference(generic):
    pts, out = generic
    check_against_reference(pts, out)
    # normal points from pb to pa
    diff = out["pa"] - out["pb"]
    proj = np.einsum("ij,ij->i", diff, out["normal"])
    assert np.allclose(proj, out["dist"], rtol=1e-10, atol=1e-14)


def test_random_parallel_pairs_take_middle_of_overlap(rng):
    n = 600
    p0 = rng.uniform(-1, 1, (n, 3))
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    lp = rng.uniform(0.2, 2.0, n)
    lam = rng.uniform(0.2, 2.0, n) * rng.choice([-1.0, 1.0], n)
    side = rng.normal(size=(n, 3))
    side -= np.einsum("ij,ij->i", side, u)[:, None] * u
    side *= rng.uniform(0.01, 1.0, n)[:, None] / np.linalg.norm(side, axis=1)[:, None]
    shift = rng.uniform(-2.5, 2.5, n)
    p1 = p0 + lp[:, None] * u
    q0 = p0 + side + shift[:, None] * u
    q1 = q0 + (lam * lp)[:, None] * u
    out = closest_points(p0, p1, q0, q1)
    check_against_reference((p0, p1, q0, q1), out)
    # overlap of Q's projection on P, in P's parameter
    sq0 = shift / lp
    sq1 = (shift + lam * lp) / lp
    lo = np.maximum(0.0, np.minimum(sq0, sq1))
    hi = np.minimum(1.0, np.maximum(sq0, sq1))
    over = lo <= hi
    assert over.sum() > 100 and (~over).sum() > 100
    assert np.allclose(out["s"][over], 0.5 * (lo + hi)[over], atol=1e-9)
    assert np.allclose(out["dist"][over], np.linalg.norm(side, axis=1)[over], rtol=1e-12)
    # disjoint: nearest ends
    s_end = np.where(np.maximum(sq0, sq1) < 0, 0.0, 1.0)
    assert np.array_equal(out["s"][~over], s_end[~over])
    assert np.all((out["t"][~over] == 0.0) | (out["t"][~over] == 1.0))


def test_random_intersecting_pairs(rng):
    n = 400
    x = rng.uniform(-1, 1, (n, 3))
    u = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3))
    a, b = rng.uniform(0.05, 0.95, n), rng.uniform(0.05, 0.95, n)
    p0, p1 = x - a[:, None] * u, x + (1 - a)[:, None] * u
    q0, q1 = x - b[:, None] * v, x + (1 - b)[:, None] * v
    out = closest_points(p0, p1, q0, q1)
    assert np.all(out["dist"] < 1e-14 * 10)
    c = np.cross(u, v)
    c /= np.linalg.norm(c, axis=1)[:, None]
    assert np.allclose(np.abs(np.einsum("ij,ij->i", out["normal"], c)), 1.0, atol=1e-9)
    assert np.allclose(out["s"], a, atol=1e-8)
    assert np.allclose(out["t"], b, atol=1e-8)
    # near-touching crossings (Q lifted by h along dP x dQ): the normal stays exactly
    # perpendicular to both segments and the distance is h to the rounding of the inputs
    h = 10.0 ** rng.uniform(-10, -3, n)
    out = closest_points(p0, p1, q0 + h[:, None] * c, q1 + h[:, None] * c)
    assert np.all(np.einsum("ij,ij->i", out["normal"], -c) > 1 - 1e-14)
    assert np.allclose(out["dist"], h, rtol=1e-5, atol=0)


def test_no_nan_on_degenerate_batch(rng):
    z = np.zeros(3)
    o = np.ones(3)
    ex = np.array([1.0, 0, 0])
    cases = [
        (z, z, z, z),
        (o, o, o, o),
        (z, z, ex, ex),
        (z, ex, z, ex),
        (z, ex, ex, z),
        (z, ex, 0.5 * ex, 0.5 * ex),
        (0.5 * ex, 0.5 * ex, z, ex),
        (z, 2 * ex, 3 * ex, 4 * ex),
        (z, ex, z, 1e-300 * ex),
        (1e-200 * o, -1e-200 * o, 1e-200 * ex, 3e-200 * o),
        (1e200 * o, -1e200 * o, 1e200 * ex, 3e200 * o),
        (1e200 * o, 1e200 * o, 1e200 * o, 1e200 * o),
        (1e3 * o, 1e3 * o + 1e-300 * ex, 1e3 * o, 1e3 * o),
        (z, ex, np.array([0, 1e-320, 0]), np.array([1.0, 1e-320, 0])),
    ]
    p0, p1, q0, q1 = (np.array(v) for v in zip(*cases))
    # plus random degenerate mixtures
    rp = random_pairs(rng, 200)
    rp = [np.concatenate([x, y]) for x, y in zip((p0, p1, q0, q1), rp)]
    m = len(cases)
    rp[1][m:m + 50] = rp[0][m:m + 50]
    rp[3][m + 50:m + 100] = rp[2][m + 50:m + 100]
    rp[1][m + 100:m + 150] = rp[0][m + 100:m + 150]
    rp[3][m + 100:m + 150] = rp[2][m + 100:m + 150]
    out = closest_points(*rp)
    for k, v in out.items():
        assert np.all(np.isfinite(v)), k
    assert np.allclose(np.linalg.norm(out["normal"], axis=1), 1.0, atol=1e-12)
    assert np.all((out["s"] >= 0) & (out["s"] <= 1) & (out["t"] >= 0) & (out["t"] <= 1))
    # finite, ordinary cases against the reference
    _, _, dref = reference(*(v[m:] for v in rp))
    assert np.allclose(out["dist"][m:], dref, rtol=1e-9, atol=1e-15)
    ordinary = [i for i in range(m) if i not in (9, 10, 11)]
    _, _, dref = reference(*(v[ordinary] for v in rp))
    assert np.allclose(out["dist"][ordinary], dref, rtol=1e-12, atol=1e-300)
    # extreme magnitudes: same geometry as the unit-scale pair, scaled
    _, _, dunit = reference(o, -o, ex, 3 * o)
    assert out["dist"][9] == pytest.approx(1e-200 * dunit[0], rel=1e-12)
    assert out["dist"][10] == pytest.approx(1e200 * dunit[0], rel=1e-12)
    assert out["dist"][11] == 0.0


# --------------------------------------------------------------------------------------------
# explicit cases
# --------------------------------------------------------------------------------------------


def test_perpendicular_skew():
    r = cp((-1, 0, 0), (1, 0, 0), (0, -1, 1), (0, 1, 1))
    assert r["dist"] == pytest.approx(1.0, abs=1e-15)
    assert r["s"] == pytest.approx(0.5, abs=1e-15)
    assert r["t"] == pytest.approx(0.5, abs=1e-15)
    assert np.allclose(r["normal"], (0, 0, -1), atol=1e-15)


def test_parallel_partial_overlap_middle():
    r = cp((0, 0, 0), (2, 0, 0), (1, 0.5, 0), (3, 0.5, 0))
    assert r["s"] == pytest.approx(0.75, abs=1e-15)
    assert r["t"] == pytest.approx(0.25, abs=1e-15)
    assert r["dist"] == 0.5
    assert np.allclose(r["normal"], (0, -1, 0), atol=1e-15)
    # Q contained in P
    r = cp((0, 0, 0), (4, 0, 0), (1, 0, 0.25), (2, 0, 0.25))
    assert r["s"] == pytest.approx(0.375, abs=1e-15)
    assert r["t"] == pytest.approx(0.5, abs=1e-15)
    assert r["dist"] == 0.25
    # generic direction
    u = unit((1.0, -2.0, 0.7))
    side = unit(np.cross(u, (0.3, 0.1, 1.0))) * 0.3
    r = cp((0, 0, 0), 2 * u, u + side, 3 * u + side)
    assert r["s"] == pytest.approx(0.75, abs=1e-12)
    assert r["t"] == pytest.approx(0.25, abs=1e-12)
    assert r["dist"] == pytest.approx(0.3, rel=1e-14)


def test_antiparallel_overlap_middle():
    r = cp((0, 0, 0), (2, 0, 0), (3, 0.5, 0), (1, 0.5, 0))
    assert r["s"] == pytest.approx(0.75, abs=1e-15)
    assert r["t"] == pytest.approx(0.75, abs=1e-15)
    assert r["dist"] == 0.5
    assert np.allclose(r["normal"], (0, -1, 0), atol=1e-15)


def test_parallel_disjoint_nearest_ends():
    r = cp((0, 0, 0), (1, 0, 0), (3, 0.5, 0), (2, 0.5, 0))
    assert (r["s"], r["t"]) == (1.0, 1.0)
    assert r["dist"] == pytest.approx(math.hypot(1.0, 0.5), rel=1e-15)
    r = cp((0, 0, 0), (1, 0, 0), (-3, 0.5, 0), (-2, 0.5, 0))
    assert (r["s"], r["t"]) == (0.0, 1.0)
    assert r["dist"] == pytest.approx(math.hypot(2.0, 0.5), rel=1e-15)


def test_collinear_overlapping():
    for u in (np.array([1.0, 0, 0]), unit((1.0, 2.0, 3.0)), unit((-0.3, 0.0, 1e-3))):
        a = np.array([0.2, -0.1, 0.4])
        r = cp(a, a + 2 * u, a + u, a + 3 * u)
        assert r["dist"] < 1e-14
        assert r["s"] == pytest.approx(0.75, abs=1e-12)
        assert r["t"] == pytest.approx(0.25, abs=1e-12)
        assert np.all(np.isfinite(r["normal"]))
        assert np.linalg.norm(r["normal"]) == pytest.approx(1.0, abs=1e-14)
        assert abs(r["normal"] @ u) < 1e-12


def test_collinear_disjoint():
    r = cp((0, 0, 0), (1, 0, 0), (3, 0, 0), (2, 0, 0))
    assert r["dist"] == 1.0
    assert (r["s"], r["t"]) == (1.0, 1.0)
    assert np.allclose(r["normal"], (-1, 0, 0), atol=1e-15)
    u = unit((1.0, 2.0, 3.0))
    r = cp(-u, -2 * u, u, 3 * u)
    assert r["dist"] == pytest.approx(2.0, rel=1e-14)
    assert (r["s"], r["t"]) == (0.0, 0.0)
    assert np.allclose(r["normal"], -u, atol=1e-14)


def test_point_segment_and_point_point():
    r = cp((0.3, 1, 0), (0.3, 1, 0), (0, 0, 0), (1, 0, 0))
    assert r["dist"] == 1.0
    assert r["t"] == pytest.approx(0.3, abs=1e-15)
    assert np.allclose(r["pa"], (0.3, 1, 0))
    assert np.allclose(r["normal"], (0, 1, 0), atol=1e-15)
    r = cp((2, 1, 0), (2, 1, 0), (0, 0, 0), (1, 0, 0))
    assert r["dist"] == pytest.approx(math.sqrt(2.0), rel=1e-15)
    assert r["t"] == 1.0
    # degenerate Q
    r = cp((0, 0, 0), (1, 0, 0), (0.3, 0, 2), (0.3, 0, 2))
    assert r["dist"] == 2.0
    assert r["s"] == pytest.approx(0.3, abs=1e-15)
    assert np.allclose(r["normal"], (0, 0, -1), atol=1e-15)
    # point on segment: zero distance, normal perpendicular to the segment
    r = cp((0.3, 0, 0), (0.3, 0, 0), (0, 0, 0), (1, 0, 0))
    assert r["dist"] == 0.0
    assert abs(r["normal"][0]) < 1e-15 and np.linalg.norm(r["normal"]) == pytest.approx(1.0)
    # point-point
    r = cp((1, 2, 3), (1, 2, 3), (1, 2, 5), (1, 2, 5))
    assert r["dist"] == 2.0
    assert np.allclose(r["normal"], (0, 0, -1), atol=1e-15)
    r = cp((1, 2, 3), (1, 2, 3), (1, 2, 3), (1, 2, 3))
    assert r["dist"] == 0.0
    assert np.linalg.norm(r["normal"]) == pytest.approx(1.0)


def test_intersecting_segments():
    r = cp((-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0))
    assert r["dist"] == 0.0
    assert (r["s"], r["t"]) == (0.5, 0.5)
    assert np.allclose(r["normal"], (0, 0, 1), atol=1e-15)  # midpoints coincide: dP x dQ
    # generic crossing; orientation from midpoint P - midpoint Q
    u, v = np.array([1.0, 0.2, -0.1]), np.array([0.1, 1.0, 0.3])
    x = np.array([0.1, 0.2, 0.3])
    p0, p1 = x - 0.25 * u, x + 0.75 * u
    q0, q1 = x - 0.5 * v, x + 0.5 * v
    r = cp(p0, p1, q0, q1)
    assert r["dist"] < 1e-15
    c = unit(np.cross(u, v))
    assert abs(abs(r["normal"] @ c) - 1.0) < 1e-12
    side = 0.5 * (p0 + p1) - 0.5 * (q0 + q1)
    assert r["normal"] @ side >= 0
    # T junction: end of P on the interior of Q
    # (midpoint difference is perpendicular to dP x dQ, so the cross product is kept as is)
    r = cp((0.5, 0, 0), (0.5, 1, 0), (0, 0, 0), (1, 0, 0))
    assert r["dist"] == 0.0 and (r["s"], r["t"]) == (0.0, 0.5)
    assert np.allclose(r["normal"], (0, 0, -1), atol=1e-15)


@pytest.mark.parametrize("offset", [0.5, 1e-3, 0.0])
def test_nearly_parallel_continuity(offset):
    """Distance is continuous through the parallel threshold (|sin| = 1e-6).

    Below the threshold the contact is the middle of the overlap, which overestimates the
    true minimum by at most min(theta L, (theta L)^2 / (2 d)) (L = 1.4 here); above it the
    general solution is exact to rounding.
    """
    p0, p1 = np.array([0.0, 0, 0]), np.array([1.0, 0, 0])
    q0 = np.array([0.3, offset, 0.0])
    L = 1.4
    base = None
    for ang in [0.0, 1e-12, 1e-9, 1e-7, 1e-6, 1.001e-6, 1e-5, 1e-3]:
        q1 = q0 + L * np.array([math.cos(ang), 0.0, math.sin(ang)])
        r = cp(p0, p1, q0, q1)
        _, _, dref = reference(p0, p1, q0, q1)
        dref = dref[0]
        assert np.all(np.isfinite(r["normal"])) and abs(np.linalg.norm(r["normal"]) - 1) < 1e-12
        bound = 1e-9 * dref + 1e-15
        if math.sin(ang) <= 1e-6:  # parallel branch
            tl = ang * L
            bound += min(tl, tl * tl / (2 * dref)) if dref > 0 else tl
        assert r["dist"] >= dref - 1e-15
        assert r["dist"] - dref <= bound, (ang, r["dist"], dref)
        if ang == 0.0:
            base = r["dist"]
            assert r["s"] == pytest.approx(0.65, abs=1e-15)  # middle of the overlap [0.3, 1]
        if ang == 1e-9:
            assert abs(r["dist"] - base) <= 1e-9
            assert r["s"] == pytest.approx(0.65, abs=1e-9)


def test_swap_reverse_rigid_invariance(generic, rng):
    (p0, p1, q0, q1), out = generic
    sw = closest_points(q0, q1, p0, p1)
    assert np.allclose(sw["dist"], out["dist"], rtol=1e-12, atol=1e-15)
    assert np.allclose(sw["normal"], -out["normal"], atol=1e-9)
    assert np.allclose(sw["s"], out["t"], atol=1e-8)
    assert np.allclose(sw["t"], out["s"], atol=1e-8)
    rv = closest_points(p1, p0, q0, q1)
    assert np.allclose(rv["dist"], out["dist"], rtol=1e-12, atol=1e-15)
    assert np.allclose(rv["s"], 1 - out["s"], atol=1e-8)
    assert np.allclose(rv["normal"], out["normal"], atol=1e-9)
    R = random_rotation(rng)
    T = np.array([0.7, -1.3, 2.9])
    rt = closest_points(*(v @ R.T + T for v in (p0, p1, q0, q1)))
    assert np.allclose(rt["dist"], out["dist"], rtol=1e-11, atol=1e-14)
    assert np.allclose(rt["s"], out["s"], atol=1e-8)
    assert np.allclose(rt["t"], out["t"], atol=1e-8)
    assert np.allclose(rt["normal"], out["normal"] @ R.T, atol=1e-8)


def test_swap_parallel_and_intersecting_cases():
    for args in [((0, 0, 0), (2, 0, 0), (1, 0.5, 0), (3, 0.5, 0)),
                 ((0, 0, 0), (2, 0, 0), (3, 0.5, 0), (1, 0.5, 0)),
                 ((-1, 0, 0), (1, 0, 0), (0.1, -1, 0), (0.1, 2, 0))]:
        a = cp(*args)
        b = cp(args[2], args[3], args[0], args[1])
        assert a["dist"] == pytest.approx(b["dist"], abs=1e-15)
        assert (a["s"], a["t"]) == pytest.approx((b["t"], b["s"]), abs=1e-15)
        assert np.allclose(a["normal"], -b["normal"], atol=1e-15)


def test_huge_offset_accuracy(rng):
    # dyadic coordinates so that the shifted inputs are exact translates of the originals
    n = 2000
    pts = [np.round(v * 2**30) / 2**30 for v in random_pairs(rng, n)]
    offset = np.array([1024.375, -987.25, 1500.125])
    big = [v + offset for v in pts]
    assert all(np.array_equal(b - offset, v) for b, v in zip(big, pts))
    out = closest_points(*big)
    _, _, dref = reference(*pts)
    assert np.all(np.abs(out["dist"] - dref) <= 1e-9 * dref)
    # touching pair far from the origin: zero distance, normal along dP x dQ
    r = cp(offset + (-1, 0, 0), offset + (1, 0, 0), offset + (0.25, -1, 0), offset + (0.25, 1, 0))
    assert r["dist"] < 1e-12
    assert np.allclose(np.abs(r["normal"]), (0, 0, 1), atol=1e-12)


# --------------------------------------------------------------------------------------------
# device functions used from other kernels
# --------------------------------------------------------------------------------------------


@wp.kernel
def _gap_kernel(
    p0: wp.array(dtype=wp.vec3d),
    p1: wp.array(dtype=wp.vec3d),
    q0: wp.array(dtype=wp.vec3d),
    q1: wp.array(dtype=wp.vec3d),
    ra: wp.float64,
    rb: wp.float64,
    out: wp.array(dtype=wp.float64),
    pts: wp.array(dtype=wp.vec3d),
):
    i = wp.tid()
    pair = closest_points_segments(p0[i], p1[i], q0[i], q1[i])
    out[i] = capsule_gap(pair, ra, rb)
    pts[2 * i] = pair.pa
    pts[2 * i + 1] = pair.pb


def test_capsule_gap_and_points(generic):
    _warp.init()
    (p0, p1, q0, q1), out = generic
    n = 64
    arrs = [wp.array(v[:n], dtype=wp.vec3d) for v in (p0, p1, q0, q1)]
    gap = wp.zeros(n, dtype=wp.float64)
    pts = wp.zeros(2 * n, dtype=wp.vec3d)
    wp.launch(_gap_kernel, dim=n, inputs=[*arrs, wp.float64(0.01), wp.float64(0.02), gap, pts])
    assert np.allclose(gap.numpy(), out["dist"][:n] - 0.03, rtol=0, atol=1e-15)
    pts = pts.numpy()
    assert np.allclose(pts[0::2], out["pa"][:n], atol=1e-14)
    assert np.allclose(pts[1::2], out["pb"][:n], atol=1e-14)
    assert SegmentPair is narrowphase.SegmentPair
