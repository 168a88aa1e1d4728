"""Exact Gauss linking integral of segment pairs (Warp kernel) against known answers."""

import math

import numpy as np
import pytest

from rodwarp.analysis import average_crossing_number, gauss_linking, linking_number
from rodwarp.errors import RodwarpError


def test_reference_segment_pairs():
    # docs/fields.md, "Checks with known answers"
    g = gauss_linking([[-1, 0, 0], [0, 0, 0]], [[1, 0, 0], [1, 0, 0]], [[0, -1, 1], [0, 0, 1]], [[0, 1, 1], [0, 1, 1]])
    assert g[0] == pytest.approx(-1 / 6, abs=1e-15)
    assert abs(g[1]) == pytest.approx(1 / 24, abs=1e-15)


def test_perpendicular_infinite_lines_limit():
    # two long perpendicular lines one unit apart: |G| -> 1/2 (half the mean number of projected
    # crossings, which is 1 for two skew infinite lines)
    L = 1e6
    g = gauss_linking([-L, 0, 0], [L, 0, 0], [0, -L, 1], [0, L, 1])[0]
    assert abs(g) == pytest.approx(0.5, abs=1e-5)
    assert abs(g) < 0.5


def test_degenerate_pairs_give_zero():
    # coplanar crossing, collinear, parallel, touching at an end, zero-length
    cases = [
        ([-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]),
        ([0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]),
        ([0, 0, 0], [1, 0, 0], [0, 1, 1], [1, 1, 1]),
        ([0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 1, 1]),
        ([0, 0, 0], [0, 0, 0], [0, 1, 1], [1, 1, 1]),
    ]
    g = gauss_linking(*[np.array(c) for c in zip(*cases)])
    assert np.all(g == 0.0)


def test_sign_flips_with_orientation_and_mirror():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(4, 500, 3))
    g = gauss_linking(*p)
    assert np.all(np.abs(g) < 0.5)
    np.testing.assert_allclose(gauss_linking(p[1], p[0], p[2], p[3]), -g, atol=1e-15)
    np.testing.assert_allclose(gauss_linking(p[2], p[3], p[0], p[1]), g, atol=1e-15)  # symmetric
    mirror = np.array([1, 1, -1])
    np.testing.assert_allclose(gauss_linking(*(p * mirror)), -g, atol=1e-15)


def test_rigid_motion_invariance():
    rng = np.random.default_rng(4)
    p = rng.normal(size=(4, 300, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))  # a rotation
    moved = p @ q.T + np.array([3.0, -7.0, 11.0])
    np.testing.assert_allclose(gauss_linking(*moved), gauss_linking(*p), atol=1e-13)
    np.testing.assert_allclose(gauss_linking(*(2.5 * p)), gauss_linking(*p), atol=1e-14)  # scale free


def _circle(n, centre, normal_axis, radius=1.0, phase=0.0):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False) + phase
    c, s = radius * np.cos(t), radius * np.sin(t)
    z = np.zeros_like(t)
    pts = {2: np.c_[c, s, z], 1: np.c_[c, z, s], 0: np.c_[z, c, s]}[normal_axis]
    return pts + np.asarray(centre, float)


@pytest.mark.parametrize("n", [3, 4, 100, 1000])
def test_hopf_link_linking_number_is_one(n):
    a = _circle(n, [0, 0, 0], 2)
    b = _circle(n, [1, 0, 0], 1, phase=0.1)
    lk = linking_number(a, b)
    assert abs(abs(lk) - 1.0) < 1e-12
    assert linking_number(a[::-1], b) == pytest.approx(-lk, abs=1e-12)


def test_unlinked_and_torus_link():
    a = _circle(400, [0, 0, 0], 2)
    b = _circle(400, [3, 0, 0], 1)
    assert abs(linking_number(a, b)) < 1e-12
    # torus link T(2, 4): two components on a torus winding twice around the core -> Lk = 2
    t = np.linspace(0, 2 * np.pi, 2000, endpoint=False)

    def torus(phase):
        u = t  # once around the core axis
        v = 2 * t + phase  # twice around the tube
        return np.c_[(2 + np.cos(v)) * np.cos(u), (2 + np.cos(v)) * np.sin(u), np.sin(v)]

    assert abs(abs(linking_number(torus(0.0), torus(np.pi))) - 2.0) < 1e-10


def test_acn_of_open_curves_invariances():
    rng = np.random.default_rng(7)
    a = np.cumsum(rng.normal(size=(30, 3)), axis=0)
    b = np.cumsum(rng.normal(size=(25, 3)), axis=0) + 2
    acn = average_crossing_number(a, b)
    assert acn > 0
    assert average_crossing_number(a[::-1], b) == pytest.approx(acn, abs=1e-12)
    assert average_crossing_number(b, a) == pytest.approx(acn, abs=1e-12)
    # subdividing every edge leaves the ACN unchanged (each edge stays straight)
    mid = 0.5 * (a[1:] + a[:-1])
    fine = np.empty((2 * len(a) - 1, 3))
    fine[0::2], fine[1::2] = a, mid
    assert average_crossing_number(fine, b) == pytest.approx(acn, abs=1e-12)


def test_bad_input_one_line():
    with pytest.raises(RodwarpError, match="NaN"):
        gauss_linking([0, 0, np.nan], [1, 0, 0], [0, 1, 1], [1, 1, 1])
    with pytest.raises(RodwarpError, match="shape"):
        gauss_linking(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(RodwarpError, match="same number"):
        gauss_linking(np.zeros((3, 3)), np.zeros((2, 3)), np.zeros((3, 3)), np.zeros((3, 3)))
    assert math.isfinite(linking_number(_circle(3, [0, 0, 0], 2), _circle(3, [5, 0, 0], 2)))


def _rectangle_solid_angle(x1, x2, y1, y2, h):
    """Solid angle of the rectangle [x1, x2] x [y1, y2] (z = 0) seen from (0, 0, h), closed form."""
    out = 0.0
    for x, sx in ((x2, 1), (x1, -1)):
        for y, sy in ((y2, 1), (y1, -1)):
            out += sx * sy * np.arctan(x * y / (h * np.sqrt(x * x + y * y + h * h)))
    return out


@pytest.mark.parametrize("gap", [1e-2, 1e-4, 1e-6, 1e-7])
def test_nearly_touching_perpendicular_pairs_full_accuracy(gap):
    # perpendicular unit segments crossing at (s, t) of their lengths, a gap apart; the difference
    # quadrilateral is a rectangle, so G = Omega / (4 pi) in closed form.  s = t puts the crossing
    # on a diagonal of the quadrilateral, where a two-triangle split loses ~1e-16 / gap.
    rng = np.random.default_rng(11)
    st = np.vstack([rng.uniform(0.05, 0.95, (20, 2)), np.c_[np.linspace(0.1, 0.9, 9), np.linspace(0.1, 0.9, 9)]])
    p1 = np.c_[-st[:, 0], np.zeros(len(st)), np.zeros(len(st))]
    p2 = p1 + [1.0, 0.0, 0.0]
    p3 = np.c_[np.zeros(len(st)), -st[:, 1], np.full(len(st), gap)]
    p4 = p3 + [0.0, 1.0, 0.0]
    g = gauss_linking(p1, p2, p3, p4)
    # difference vectors p - q span x in [-s, 1 - s], y in [t - 1, t], z = -gap
    exact = np.array([_rectangle_solid_angle(-s, 1 - s, t - 1, t, gap) for s, t in st]) / (4 * np.pi)
    np.testing.assert_allclose(np.abs(g), np.abs(exact), rtol=0, atol=2e-15)
    assert np.all(np.abs(g) < 0.5)
