"""Local fields on voxel grids (Warp kernels) against exact answers and an independent NumPy oracle."""

import math

import numpy as np
import pytest

from rodwarp.analysis import _fields as F
from rodwarp.analysis import compute_fields
from rodwarp.errors import RodwarpError
from rodwarp.rodset import Contacts, RodSet

LONG = 50.0


def _one_ball(rods, centre, R, **kw):
    """Fields at a single ball centre: a 3x3x3 grid of spacing R around it, read at the middle."""
    c = np.asarray(centre, float)
    f = compute_fields(rods, radius=R, spacing=R, domain=[c - R, c + R], keep_outside=True, **kw)
    assert f.shape == (3, 3, 3)
    np.testing.assert_allclose([f.x[1], f.y[1], f.z[1]], c, atol=1e-12)
    return {k: getattr(f, k)[1, 1, 1] for k in ("phi", "S", "c", "e", "n", "contacts")}, f


def _lines(*segs, radius=0.01):
    return RodSet.from_polylines([np.asarray(s, float) for s in segs], radii=radius)


def test_crossing_lines_exact_e():
    # docs/fields.md, "Checks with known answers": e = asin(3/7) / pi at (0, 0, 0.5), R = 1; 0 at (0, 0, 2.5)
    rods = _lines([[-LONG, 0, 0], [LONG, 0, 0]], [[0, -LONG, 1], [0, LONG, 1]])
    v, _ = _one_ball(rods, [0, 0, 0.5], 1.0)
    assert abs(v["e"] - 0.1409829640286239) < 1e-12
    assert v["n"] == 2
    v, _ = _one_ball(rods, [0, 0, 2.5], 1.0)
    assert v["e"] == 0.0 and v["n"] == 0


def test_clipping_is_independent_of_discretisation():
    # the authors' both-ends-inside rule gave 5.61, 8.61, 9.04, 9.14 for 1, 3, 7, 50 subdivisions;
    # exact clipping gives one value for every subdivision
    rng = np.random.default_rng(0)
    a0, a1 = np.array([-1.3, -0.2, -0.1]), np.array([1.2, 0.3, 0.2])
    b0, b1 = np.array([0.1, -1.4, 0.35]), np.array([-0.2, 1.1, 0.25])
    values = []
    for k in (1, 3, 7, 50):
        t = np.linspace(0, 1, k + 1)[:, None]
        rods = _lines(a0 + t * (a1 - a0), b0 + t * (b1 - b0))
        v, _ = _one_ball(rods, [0.05, -0.02, 0.1], 0.9)
        values.append(v["e"])
        assert v["phi"] > 0
    assert values[0] > 0.05
    np.testing.assert_allclose(values, values[0], rtol=0, atol=1e-13)
    del rng


def test_single_rod_phi_and_S():
    R, d = 1.0, 0.02
    rods = _lines([[-LONG, 0, 0], [LONG, 0, 0]], radius=d / 2)
    v, _ = _one_ball(rods, [0, 0, 0], R)
    assert v["phi"] == pytest.approx((math.pi * d**2 / 4) * 2 * R / (4 / 3 * math.pi * R**3), rel=1e-12)
    assert v["S"] == pytest.approx(1.0, abs=1e-12)
    assert v["n"] == 1 and v["e"] == 0.0


@pytest.mark.parametrize("dirs, expected", [
    ([[1, 0, 0], [1, 0, 0]], 1.0),  # aligned
    ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], 0.0),  # x, y, z
    ([[1, 0, 0], [0.5, math.sqrt(3) / 2, 0], [-0.5, math.sqrt(3) / 2, 0]], 0.25),  # in-plane 0/60/120 deg
    ([[0, 0, 1], [0, 0, -1], [1, 0, 0]], 0.5),  # +z, -z, +x: no head or tail
])
def test_nematic_order_cases(dirs, expected):
    # rods through (or near) the centre with equal clipped lengths; small offsets keep them apart
    segs = []
    for k, u in enumerate(dirs):
        u = np.asarray(u, float)
        off = np.array([0.0, 0.0, 0.0])
        off[(np.argmax(np.abs(u)) + 1) % 3] = 0.01 * (-1) ** k  # same distance: equal chords
        segs.append(np.stack([off - LONG * u, off + LONG * u]))
    v, _ = _one_ball(_lines(*segs, radius=0.001), [0, 0, 0], 1.0)
    assert v["S"] == pytest.approx(expected, abs=1e-6)


def test_same_rod_pairs_excluded_and_rod_counted_once():
    # one rod bent into a U passing the ball twice: n = 1 and no self-entanglement
    u = np.array([[-LONG, -0.3, 0.0], [LONG, -0.3, 0.0], [LONG, 0.3, 0.2], [-LONG, 0.3, 0.2]])
    v, _ = _one_ball(_lines(u), [0, 0, 0], 1.0)
    assert v["n"] == 1 and v["e"] == 0.0
    # a second, crossing rod brings e > 0 and n = 2
    v2, _ = _one_ball(_lines(u, [[0, -LONG, 0.5], [0, LONG, 0.5]]), [0, 0, 0], 1.0)
    assert v2["n"] == 2 and v2["e"] > 0


def test_coplanar_rods_give_zero():
    rng = np.random.default_rng(1)
    segs = [np.c_[rng.uniform(-2, 2, (5, 2)), np.zeros(5)] for _ in range(6)]
    v, _ = _one_ball(_lines(*segs), [0, 0, 0], 1.5)
    assert v["n"] >= 2 and v["e"] == 0.0


def _random_rods(n, seed, box=3.0, k=6, radius=0.02):
    rng = np.random.default_rng(seed)
    polys = []
    for _ in range(n):
        start = rng.uniform(0, box, 3)
        steps = rng.normal(size=(k - 1, 3)) * 0.4
        polys.append(np.vstack([start, start + np.cumsum(steps, axis=0)]))
    return RodSet.from_polylines(polys, radii=radius)


def test_rigid_motion_and_reversal_invariance():
    rods = _random_rods(25, 2)
    c = np.array([1.5, 1.5, 1.5])
    v, _ = _one_ball(rods, c, 1.0)
    assert v["e"] > 0.5
    rng = np.random.default_rng(9)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    shift = np.array([10.0, -4.0, 2.0])
    moved = RodSet(points=rods.points @ q.T + shift, offsets=rods.offsets, radii=rods.radii)
    vm, _ = _one_ball(moved, q @ c + shift, 1.0)
    for key in ("e", "phi", "S", "n"):
        assert vm[key] == pytest.approx(v[key], abs=1e-11)
    rev = RodSet.from_polylines([rods.rod(i)[::-1] for i in range(rods.n_rods)], radii=rods.radii)
    vr, _ = _one_ball(rev, c, 1.0)
    assert vr["e"] == pytest.approx(v["e"], abs=1e-12)


def test_against_numpy_oracle_on_random_rods():
    from rodwarp.testing.reference import fields_numpy

    rods = _random_rods(60, 5)
    contacts = Contacts(np.zeros(40, int), np.ones(40, int), np.random.default_rng(3).uniform(0, 3, (40, 3)), np.zeros(40))
    rods.contacts = contacts
    f = compute_fields(rods, radius=0.7, spacing=0.45, domain=[[0, 0, 0], [3, 3, 3]])
    Z, Y, X = np.meshgrid(f.z, f.y, f.x, indexing="ij")
    centres = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    ok = f.valid.ravel() | (f.n.ravel() == 0)
    ok &= np.isfinite(f.e.ravel())
    assert ok.sum() >= 8
    p0, p1, rod = rods.segments()
    ref = fields_numpy(p0, p1, rod, 2 * rods.radii[rod], centres[ok], 0.7, contact_points=contacts.point)
    np.testing.assert_allclose(f.e.ravel()[ok], ref["e"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(f.phi.ravel()[ok], ref["phi"], rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(f.n.ravel()[ok], ref["n"])
    np.testing.assert_array_equal(f.contacts.ravel()[ok], ref["contacts"])
    has = ref["n"] > 0
    np.testing.assert_allclose(f.S.ravel()[ok][has], ref["S"][has], atol=1e-9)


def test_defaults_masking_and_grid():
    rods = _random_rods(40, 6, box=4.0)
    rods.box = np.array([[0.0, 0.0, 0.0], [4.0, 4.0, 4.0]])
    d = float(np.mean(rods.diameters))
    l = float(np.mean(rods.rod_lengths()))
    f = compute_fields(rods)
    R = math.sqrt(d * l)
    assert f.radius == pytest.approx(R) and f.spacing == pytest.approx(R / 2)
    assert np.allclose(np.diff(f.x), R / 2)
    # masked exactly where the ball leaves the box
    inside = [(a - R >= -1e-9) & (a + R <= 4.0 + 1e-9) for a in (f.x, f.y, f.z)]
    expected = inside[2][:, None, None] & inside[1][None, :, None] & inside[0][None, None, :]
    assert 0 < expected.sum() < expected.size
    np.testing.assert_array_equal(np.isfinite(f.e), expected)
    np.testing.assert_array_equal(np.isfinite(f.phi), expected)
    kept = compute_fields(rods, keep_outside=True)
    assert np.isfinite(kept.e).all()
    inside = np.isfinite(f.e)
    np.testing.assert_array_equal(kept.e[inside], f.e[inside])


def test_contact_normalisation():
    rods = _random_rods(50, 8)
    f = compute_fields(rods, radius=0.6, spacing=0.3)
    a = f.attrs
    assert a["contact_source"].startswith("detected")
    Z = a["Z"]
    assert Z == pytest.approx(2 * a["n_contacts"] / 50)
    v = np.isfinite(f.c) & (f.contacts > 0)
    if v.any():
        np.testing.assert_allclose(f.c[v], f.contacts[v] / (a["rho"] * Z * (4 / 3 * math.pi * 0.6**3) / 2))


def test_batching_gives_identical_results(monkeypatch):
    rods = _random_rods(40, 10)
    whole = compute_fields(rods, radius=0.6, spacing=0.3)
    monkeypatch.setattr(F, "MAX_CLIPPED_PER_BATCH", 7)
    seen = []
    parts = compute_fields(rods, radius=0.6, spacing=0.3, progress=lambda d, t: seen.append((d, t)))
    assert len(seen) > 5 and seen[-1][0] == seen[-1][1]
    for k in ("phi", "S", "e", "n", "c"):
        np.testing.assert_array_equal(getattr(parts, k), getattr(whole, k))


def test_detect_contacts_crossing_pair():
    from rodwarp.rodset import detect_contacts

    r = 0.05
    touching = _lines([[-1, 0, 0], [1, 0, 0]], [[0, -1, 2 * r], [0, 1, 2 * r]], [[0, -1, 1], [0, 1, 1]], radius=r)
    c = detect_contacts(touching)
    assert len(c) == 1 and (c.rod_i[0], c.rod_j[0]) == (0, 1)
    assert abs(c.gap[0]) < 1e-12
    np.testing.assert_allclose(c.point[0], [0, 0, r], atol=1e-12)
    near = _lines([[-1, 0, 0], [1, 0, 0]], [[0, -1, 2 * r + 0.2 * r], [0, 1, 2 * r + 0.2 * r]], radius=r)
    assert len(detect_contacts(near)) == 0  # gap 0.1 d is not below d / 10


def test_bad_parameters_one_line():
    rods = _random_rods(5, 11)
    with pytest.raises(RodwarpError, match="positive"):
        compute_fields(rods, radius=-1)
    with pytest.raises(RodwarpError, match="no ball"):
        compute_fields(rods, radius=100.0)
    with pytest.raises(RodwarpError, match="0.01 to 2 R"):
        compute_fields(rods, radius=0.5, spacing=1e-5)  # a grid far finer than the balls
    with pytest.raises(RodwarpError, match="voxels"):  # a fine (but in-range) grid over a huge domain
        compute_fields(rods, radius=0.5, spacing=0.005, domain=[[0, 0, 0], [1e3, 1e3, 1e3]])
    with pytest.raises(RodwarpError, match="below half the rods' diameter"):
        compute_fields(rods, radius=1e-9)


@pytest.mark.cuda
def test_cpu_and_cuda_agree():
    rods = _random_rods(80, 12)
    a = compute_fields(rods, radius=0.6, spacing=0.3, device="cpu")
    b = compute_fields(rods, radius=0.6, spacing=0.3, device="cuda")
    for k in ("phi", "e", "c"):
        np.testing.assert_allclose(getattr(b, k), getattr(a, k), rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(a.n, b.n)
    np.testing.assert_allclose(b.S, a.S, atol=1e-9)
