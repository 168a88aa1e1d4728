"""The NumPy reference of the local fields (rodwarp.testing.reference) against known answers."""

import math

import numpy as np
import pytest

from rodwarp.testing import reference
from rodwarp.testing.reference import clip_segments_to_ball, fields_numpy, gauss_linking_numpy

E_LINES = math.asin(3.0 / 7.0) / math.pi  # 0.1409829640286239


def _rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _polyline_segments(rods):
    """rods: list of (n_i, 3) vertex arrays -> p0, p1, seg_rod."""
    p0 = np.concatenate([r[:-1] for r in rods])
    p1 = np.concatenate([r[1:] for r in rods])
    rod = np.concatenate([np.full(len(r) - 1, i) for i, r in enumerate(rods)])
    return p0, p1, rod


def _subdivide(a, b, k):
    t = np.linspace(0.0, 1.0, k + 1)[:, None]
    return a + t * (b - a)


# ----------------------------------------------------------------------------------------------
# Gauss integral of segment pairs
# ----------------------------------------------------------------------------------------------

def test_known_segment_pairs():
    g = gauss_linking_numpy([[-1, 0, 0], [0, 0, 0]], [[1, 0, 0], [1, 0, 0]],
                            [[0, -1, 1], [0, 0, 1]], [[0, 1, 1], [0, 1, 1]])
    assert abs(abs(g[0]) - 1.0 / 6.0) < 1e-14
    assert g[0] == pytest.approx(-1.0 / 6.0, abs=1e-14)
    assert abs(abs(g[1]) - 1.0 / 24.0) < 1e-14


def test_degenerate_pairs_give_zero():
    # coplanar crossing, parallel, collinear, touching at an endpoint, zero-length segment
    p1 = [[-1, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]
    p2 = [[1, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0], [0, 0, 0]]
    p3 = [[0, -1, 0], [0, 1, 0], [2, 0, 0], [0, 0, 0], [0, -1, 1]]
    p4 = [[0, 1, 0], [1, 1, 0], [3, 0, 0], [0, 1, 1], [0, 1, 1]]
    assert np.all(gauss_linking_numpy(p1, p2, p3, p4) == 0.0)


def test_reversal_flips_sign_and_keeps_acn():
    rng = np.random.default_rng(3)
    p = rng.uniform(size=(4, 500, 3))
    g = gauss_linking_numpy(*p)
    assert np.allclose(gauss_linking_numpy(p[1], p[0], p[2], p[3]), -g, atol=1e-14, rtol=0)
    assert np.allclose(gauss_linking_numpy(p[2], p[3], p[0], p[1]), g, atol=1e-14, rtol=0)
    assert np.all(np.abs(g) < 0.5)


def test_hopf_link_sums_to_one():
    m = 200
    t = 2 * np.pi * np.arange(m) / m
    a = np.stack([np.cos(t), np.sin(t), 0 * t], 1)
    b = np.stack([1 + np.cos(t), 0 * t, np.sin(t)], 1)
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    i, j = i.ravel(), j.ravel()
    g = gauss_linking_numpy(a[i], a[(i + 1) % m], b[j], b[(j + 1) % m])
    assert abs(abs(math.fsum(g)) - 1.0) < 1e-12
    c = b + np.array([5.0, 0, 0])  # unlinked
    g = gauss_linking_numpy(a[i], a[(i + 1) % m], c[j], c[(j + 1) % m])
    assert abs(math.fsum(g)) < 1e-12


def test_agrees_with_warp_kernel_on_random_pairs():
    from rodwarp.analysis import gauss_linking

    rng = np.random.default_rng(11)
    p = rng.uniform(-1, 1, size=(4, 2000, 3))
    # plus some near-touching perpendicular pairs
    s = rng.uniform(0.05, 0.95, 200)
    # (below gap 1e-4 the kernel's two-triangle split loses up to 1e-16 / gap near its diagonal)
    gap = 10.0 ** rng.uniform(-4, -1, 200)
    q1 = np.stack([-s, 0 * s, 0 * s], 1)
    q2 = q1 + [1.0, 0, 0]
    q3 = np.stack([0 * s, -s[::-1], gap], 1)
    q4 = q3 + [0, 1.0, 0]
    P = [np.concatenate([p[k], q]) for k, q in enumerate((q1, q2, q3, q4))]
    warp = gauss_linking(*P, device="cpu")
    for form in ("foot", "diagonal"):
        assert np.max(np.abs(gauss_linking_numpy(*P, form=form) - warp)) < 1e-12, form


def _crossing_pairs(s, t, gap, angle_deg, rng):
    """Unit segments crossing at parameters (s, t), gap apart, randomly rotated and moved."""
    n = len(s)
    th = math.radians(angle_deg)
    u2 = np.array([math.cos(th), math.sin(th), 0.0])
    p1 = -s[:, None] * np.array([1.0, 0, 0])
    p3 = -t[:, None] * u2 + [0, 0, gap]
    pts = (p1, p1 + [1.0, 0, 0], p3, p3 + u2)
    out = []
    rots = [_rotation(rng) for _ in range(n)]
    shift = rng.uniform(-1, 1, size=(n, 3))
    for p in pts:
        out.append(np.stack([r @ x for r, x in zip(rots, p)]) + shift)
    return out


@pytest.mark.parametrize("gap", [1e-5, 1e-7])
def test_foot_form_accurate_when_nearly_touching(gap):
    """Crossing within a few gaps of the a-c diagonal (the Warp kernel's split) and of the
    b-d diagonal: the foot form stays within 1e-14 of a long-double evaluation of the split
    whose diagonal is far from the crossing."""
    rng = np.random.default_rng(23)
    s = rng.uniform(0.1, 0.9, 300)
    off = rng.uniform(-3, 3, 300) * gap
    for t, ref_form in ((s + off, "diagonal"), (1.0 - s + off, None)):
        P = _crossing_pairs(s, t, gap, 70.0, rng)
        foot = gauss_linking_numpy(*P)
        if ref_form is None:  # near b-d: compare with the foot form in long double
            ref = reference._gauss_cf(*(np.ascontiguousarray(p.T).astype(np.longdouble) for p in P))
        else:                 # near a-c: the b-d split is well conditioned there
            ref = reference._gauss_cf(*(np.ascontiguousarray(p.T).astype(np.longdouble) for p in P),
                                      form=ref_form)
        assert np.max(np.abs(foot - ref.astype(float))) < 1e-14
        assert np.all(np.abs(foot) < 0.5) and np.median(np.abs(foot)) > 0.49


# ----------------------------------------------------------------------------------------------
# clipping
# ----------------------------------------------------------------------------------------------

def test_clip_cases():
    x = np.zeros(3)
    p0 = np.array([[-3, 0, 0], [-0.5, 0, 0], [0.5, 0, 0], [-3, 1, 0], [-3, 2, 0], [-3, 0.6, 0]], float)
    p1 = np.array([[3, 0, 0], [0.5, 0, 0], [3, 0, 0], [3, 1, 0], [3, 2, 0], [0, 0.6, 0]], float)
    q0, q1, L = clip_segments_to_ball(p0, p1, x, 1.0)
    assert L == pytest.approx([2.0, 1.0, 0.5, 0.0, 0.0, 0.8], abs=1e-15)
    assert np.array_equal(q0[1], p0[1]) and np.array_equal(q1[1], p1[1])  # inside: untouched
    assert np.allclose(q0[0], [-1, 0, 0]) and np.allclose(q1[0], [1, 0, 0])
    assert np.allclose(q0[5], [-0.8, 0.6, 0]) and np.array_equal(q1[5], p1[5])


# ----------------------------------------------------------------------------------------------
# fields: e
# ----------------------------------------------------------------------------------------------

def _two_lines(n_sub=1):
    a = _subdivide(np.array([-10.0, 0, 0]), np.array([10.0, 0, 0]), n_sub)
    b = _subdivide(np.array([0, -10.0, 1]), np.array([0, 10.0, 1]), n_sub)
    return _polyline_segments([a, b])


def test_two_lines_known_answer():
    p0, p1, rod = _two_lines()
    f = fields_numpy(p0, p1, rod, 0.01, [[0, 0, 0.5], [0, 0, 2.5]], 1.0)
    assert abs(f["e"][0] - E_LINES) < 1e-12
    assert f["e"][1] == 0.0
    assert f["n"].tolist() == [2, 0]
    # both lines lie at distance 1/2 from the centre: chord 2 sqrt(3/4) each
    assert f["length"][0] == pytest.approx(2 * math.sqrt(3.0), abs=1e-14)


@pytest.mark.parametrize("n_sub", [3, 7, 50])
def test_subdividing_straight_rods_leaves_e_unchanged(n_sub):
    p0, p1, rod = _two_lines(n_sub)
    f = fields_numpy(p0, p1, rod, 0.01, [[0, 0, 0.5]], 1.0)
    assert abs(f["e"][0] - E_LINES) < 1e-12
    # skew rods with ends inside and outside the ball
    rng = np.random.default_rng(5)
    ends = rng.uniform(-1.2, 1.2, size=(6, 2, 3))
    centers = rng.uniform(-0.3, 0.3, size=(5, 3))
    one = fields_numpy(*_polyline_segments([e for e in ends]), 0.01, centers, 1.0)
    many = fields_numpy(*_polyline_segments([_subdivide(e[0], e[1], n_sub) for e in ends]), 0.01, centers, 1.0)
    assert np.max(np.abs(one["e"] - many["e"])) < 1e-12
    assert np.max(np.abs(one["length"] - many["length"])) < 1e-12
    assert np.array_equal(one["n"], many["n"])
    assert np.all(one["e"] > 0)


def test_rigid_motion_leaves_fields_unchanged():
    rng = np.random.default_rng(7)
    rods = [np.cumsum(rng.normal(scale=0.25, size=(10, 3)), 0) + rng.uniform(-0.5, 0.5, 3) for _ in range(12)]
    p0, p1, rod = _polyline_segments(rods)
    centers = rng.uniform(-0.5, 0.5, size=(20, 3))
    f = fields_numpy(p0, p1, rod, 0.02, centers, 0.6)
    Rm, t = _rotation(rng), rng.uniform(-5, 5, 3)
    g = fields_numpy(p0 @ Rm.T + t, p1 @ Rm.T + t, rod, 0.02, centers @ Rm.T + t, 0.6)
    assert f["e"].max() > 0.1
    assert np.max(np.abs(f["e"] - g["e"])) < 1e-12
    assert np.max(np.abs(f["S"] - g["S"])) < 1e-12
    assert np.max(np.abs(f["phi"] - g["phi"])) < 1e-14
    assert np.array_equal(f["n"], g["n"])
    # reversing every rod changes nothing either
    h = fields_numpy(p1[::-1], p0[::-1], rod[::-1], 0.02, centers, 0.6)
    assert np.max(np.abs(f["e"] - h["e"])) < 1e-12


def test_coplanar_rods_give_zero():
    rng = np.random.default_rng(2)
    rods = []
    for _ in range(8):
        v = np.cumsum(rng.normal(scale=0.3, size=(6, 3)), 0)
        v[:, 2] = 0.0
        rods.append(v)
    Rm = _rotation(rng)
    p0, p1, rod = _polyline_segments([r @ Rm.T for r in rods])
    f = fields_numpy(p0, p1, rod, 0.01, rng.uniform(-0.5, 0.5, size=(10, 3)) @ Rm.T, 1.0)
    assert f["n"].max() >= 2
    assert np.all(f["e"] == 0.0)


def test_same_rod_pairs_excluded():
    t = np.linspace(0, 4 * np.pi, 60)
    helix = np.stack([0.5 * np.cos(t), 0.5 * np.sin(t), 0.05 * t - 0.3], 1)
    p0, p1, rod = _polyline_segments([helix])
    f = fields_numpy(p0, p1, rod, 0.01, [[0, 0, 0]], 1.0)
    assert f["n"][0] == 1 and f["e"][0] == 0.0
    # the same segments split into two rods do count
    rod2 = (np.arange(len(rod)) >= len(rod) // 2).astype(int)
    g = fields_numpy(p0, p1, rod2, 0.01, [[0, 0, 0]], 1.0)
    assert g["n"][0] == 2 and g["e"][0] > 0.1


def test_matches_brute_force_with_warp_acn():
    """Random bent rods: e against a per-centre loop of scalar clipping + rodwarp.analysis."""
    from rodwarp.analysis import gauss_linking

    rng = np.random.default_rng(13)
    rods = [np.cumsum(rng.normal(scale=0.15, size=(10, 3)), 0) + rng.uniform(0, 1, 3) for _ in range(25)]
    p0, p1, rod = _polyline_segments(rods)
    centers = rng.uniform(0, 1, size=(12, 3))
    R = 0.35
    f = fields_numpy(p0, p1, rod, 0.01, centers, R, chunk=5)
    for c, x in enumerate(centers):
        segs = []
        for s in range(len(p0)):
            d = p1[s] - p0[s]
            # scalar quadratic, textbook form
            A, B, C = d @ d, 2 * d @ (p0[s] - x), (p0[s] - x) @ (p0[s] - x) - R * R
            disc = B * B - 4 * A * C
            if disc <= 0:
                continue
            t0 = max((-B - math.sqrt(disc)) / (2 * A), 0.0)
            t1 = min((-B + math.sqrt(disc)) / (2 * A), 1.0)
            if t1 > t0:
                segs.append((p0[s] + t0 * d, p0[s] + t1 * d, rod[s]))
        i, j = np.triu_indices(len(segs), 1)
        keep = np.array([segs[a][2] != segs[b][2] for a, b in zip(i, j)], bool)
        i, j = i[keep], j[keep]
        g = gauss_linking(np.array([segs[a][0] for a in i]), np.array([segs[a][1] for a in i]),
                          np.array([segs[b][0] for b in j]), np.array([segs[b][1] for b in j]))
        assert abs(np.abs(g).sum() - f["e"][c]) < 1e-10
        assert f["n"][c] == len({s[2] for s in segs})
    assert f["e"].max() > 0.5


def test_pair_batches_and_chunks_do_not_change_results(monkeypatch):
    rng = np.random.default_rng(17)
    rods = [np.cumsum(rng.normal(scale=0.2, size=(8, 3)), 0) + rng.uniform(0, 1, 3) for _ in range(30)]
    p0, p1, rod = _polyline_segments(rods)
    centers = rng.uniform(0, 1, size=(40, 3))
    f = fields_numpy(p0, p1, rod, 0.01, centers, 0.4)
    monkeypatch.setattr(reference, "_PAIR_BUDGET", 7)
    g = fields_numpy(p0, p1, rod, 0.01, centers, 0.4, chunk=3)
    for k in f:
        assert np.allclose(f[k], g[k], rtol=0, atol=1e-12), k


# ----------------------------------------------------------------------------------------------
# fields: S, phi, n, contacts
# ----------------------------------------------------------------------------------------------

def _rods_through_origin(dirs, half=2.0):
    dirs = np.asarray(dirs, float)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    return [np.stack([-half * u, half * u]) for u in dirs]


@pytest.mark.parametrize("dirs, expected", [
    ([[0, 0, 1], [0, 0, 1]], 1.0),
    ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], 0.0),
    ([[1, 0, 0], [0.5, math.sqrt(3) / 2, 0], [-0.5, math.sqrt(3) / 2, 0]], 0.25),
])
def test_nematic_order_cases(dirs, expected):
    p0, p1, rod = _polyline_segments(_rods_through_origin(dirs))
    p0 = p0 + np.arange(len(p0))[:, None] * [0.01, 0.013, 0.0]  # keep them apart
    p1 = p1 + np.arange(len(p1))[:, None] * [0.01, 0.013, 0.0]
    f = fields_numpy(p0, p1, rod, 0.01, [[0, 0, 0]], 10.0)  # the ball holds every rod whole
    assert abs(f["S"][0] - expected) < 1e-12
    # a small ball through the exact centre clips every rod to the same length
    g = fields_numpy(*_polyline_segments(_rods_through_origin(dirs)), 0.01, [[0, 0, 0]], 1.0)
    assert abs(g["S"][0] - expected) < 1e-12


def test_nematic_order_head_tail_symmetric():
    # {+z, -z, +x}: 0.5 (rods have no head or tail)
    p0 = np.array([[0, 0, -1.0], [0.1, 0, 1.0], [-1.0, 0.1, 0]])
    p1 = np.array([[0, 0, 1.0], [0.1, 0, -1.0], [1.0, 0.1, 0]])
    f = fields_numpy(p0, p1, [0, 1, 2], 0.01, [[0, 0, 0]], 5.0)
    assert abs(f["S"][0] - 0.5) < 1e-12
    # a ball with no rods: S = 0, phi = 0, e = 0, n = 0
    g = fields_numpy(p0, p1, [0, 1, 2], 0.01, [[50, 0, 0]], 1.0)
    assert g["S"][0] == 0 and g["phi"][0] == 0 and g["e"][0] == 0 and g["n"][0] == 0


def test_volume_fraction_single_rod():
    d, R = 0.02, 0.3
    p0, p1, rod = _polyline_segments([_subdivide(np.array([-1.0, 0.2, 0.1]), np.array([1.0, -0.1, 0.3]), 9)])
    mid = np.array([0.0, 0.05, 0.2])  # on the rod
    f = fields_numpy(p0, p1, rod, d, [mid], R)
    expected = (math.pi * d * d / 4) * (2 * R) / (4.0 / 3.0 * math.pi * R ** 3)
    assert abs(f["phi"][0] - expected) < 1e-14
    assert f["length"][0] == pytest.approx(2 * R, abs=1e-14)
    # per-segment diameters: the same value per segment gives the same phi
    g = fields_numpy(p0, p1, rod, np.full(len(p0), d), [mid], R)
    assert g["phi"][0] == pytest.approx(f["phi"][0], rel=1e-14)
    # a thicker half doubles the diameter on the segments with x > 0
    dd = np.where(0.5 * (p0[:, 0] + p1[:, 0]) > 0, 2 * d, d)
    h = fields_numpy(p0, p1, rod, dd, [mid], R)
    assert h["phi"][0] > f["phi"][0]


def test_contacts_and_rod_labels():
    p0 = np.array([[-1, 0, 0], [0, -1, 0.1], [5, 5, 5]], float)
    p1 = np.array([[1, 0, 0], [0, 1, 0.1], [6, 5, 5]], float)
    cps = np.array([[0, 0, 0.05], [0.9, 0, 0], [0, 0, 1.5], [3, 3, 3]])
    f = fields_numpy(p0, p1, [42, -7, 3], 0.01, [[0, 0, 0], [10, 10, 10]], 1.0, contact_points=cps)
    assert f["contacts"].tolist() == [2, 0]
    assert f["n"].tolist() == [2, 0]
    assert fields_numpy(p0, p1, [0, 1, 2], 0.01, [[0, 0, 0]], 1.0)["contacts"][0] == 0


def test_bad_input_is_reported():
    from rodwarp.errors import RodwarpError

    with pytest.raises(RodwarpError):
        fields_numpy(np.zeros((2, 3)), np.ones((3, 3)), [0, 1], 0.01, [[0, 0, 0]], 1.0)
    with pytest.raises(RodwarpError):
        fields_numpy(np.zeros((2, 3)), np.ones((2, 3)), [0, 1], 0.01, [[0, 0, 0]], 0.0)
