"""A packing's core and rim from its n field (rodwarp.analysis.packing_regions) against packings
of known shape, and e per rod pair ball by ball against its definition."""

import numpy as np
import pytest

from rodwarp.analysis import packing_regions, pair_entanglement
from rodwarp.errors import RodwarpError


def _cylinder(axis=(0.031, -0.012), radius=0.05, height=0.08, h=0.0025, top_cap=True):
    """n of a cylindrical packing on a plate: 10 rods per ball inside, 0 outside, a sparse rough
    top layer (a few balls) above it."""
    x = np.arange(-0.1, 0.1 + 1e-12, h) + 0.0003
    y = np.arange(-0.1, 0.1 + 1e-12, h) - 0.0007
    z = np.arange(0.005, height + 0.02, h)
    X, Y = np.meshgrid(x, y)
    inside = np.hypot(X - axis[0], Y - axis[1]) < radius
    n = np.zeros((len(z), len(y), len(x)))
    for k, zz in enumerate(z):
        if zz <= height:
            n[k][inside] = 10
        elif top_cap and zz <= height + h:
            n[k][inside & (np.hypot(X - axis[0], Y - axis[1]) < 0.2 * radius)] = 2  # a few rods on top
    return n, x, y, z


def test_the_regions_of_a_cylinder_are_its_axis_radius_and_height():
    h = 0.0025
    n, x, y, z = _cylinder(h=h)
    reg = packing_regions(n, x, y, z)
    assert reg.axis == pytest.approx((0.031, -0.012), abs=h / 4)
    assert reg.radius == pytest.approx(0.05, abs=h / 2)
    assert reg.bottom == pytest.approx(z[0])
    assert reg.top == pytest.approx(z[z <= 0.08][-1])  # the sparse top layer is not the body
    # the core: within 0.55 of the radius, 15-70% of the height; the rim: the band's other balls
    span = reg.top - reg.bottom
    zc = z[:, None, None] * np.ones_like(n)
    rr = np.hypot(x[None, None, :] - reg.axis[0], y[None, :, None] - reg.axis[1]) / reg.radius
    band = (n > 0) & (zc >= reg.bottom + 0.15 * span - 1e-12) & (zc <= reg.bottom + 0.70 * span + 1e-12)
    np.testing.assert_array_equal(reg.core, band & (rr < 0.55))
    np.testing.assert_array_equal(reg.rim, band & (rr >= 0.55))
    # their shares of the band: areas of the disc of 0.55 R and of the annulus
    assert reg.core.sum() / reg.band.sum() == pytest.approx(0.55**2, abs=0.02)
    assert reg.as_dict()["core_balls"] == reg.core.sum()


def test_the_regions_do_not_depend_on_the_grid_or_the_unit():
    n, x, y, z = _cylinder(h=0.0025)
    a = packing_regions(n, x, y, z)
    b = packing_regions(n, x * 1000, y * 1000, z * 1000)  # mm
    assert b.radius == pytest.approx(1000 * a.radius) and b.axis == pytest.approx((1000 * a.axis[0], 1000 * a.axis[1]))
    np.testing.assert_array_equal(a.core, b.core)
    n2, x2, y2, z2 = _cylinder(h=0.002)
    c = packing_regions(n2, x2, y2, z2)
    assert c.radius == pytest.approx(a.radius, abs=0.002)


def test_nan_outside_the_packing_reads_as_empty():
    n, x, y, z = _cylinder()
    m = n.copy()
    m[n == 0] = np.nan
    np.testing.assert_array_equal(packing_regions(m, x, y, z).core, packing_regions(n, x, y, z).core)


@pytest.mark.parametrize("kw, message", [
    (dict(n=np.zeros((3, 4, 5))), "no ball holds a rod"),
    (dict(n=np.ones((3, 5, 4))), "grid"),
    (dict(core_radius=0.0), "core_radius"),
    (dict(core_height=(0.7, 0.15)), "core_height"),
])
def test_bad_regions_input_is_refused(kw, message):
    args = dict(n=np.ones((3, 4, 5)), x=np.arange(5.0), y=np.arange(4.0), z=np.arange(3.0))
    args.update(kw)
    with pytest.raises(RodwarpError, match=message):
        packing_regions(args.pop("n"), args.pop("x"), args.pop("y"), args.pop("z"), **args)


def test_pair_entanglement_is_e_over_the_pairs_of_each_ball():
    e = np.array([0.0, 0.5, 3.0, 4.5, 7.0])
    n = np.array([0, 1, 2, 3, 10])
    got = pair_entanglement(e, n)
    assert np.isnan(got[0]) and np.isnan(got[1])  # no pair
    np.testing.assert_allclose(got[2:], [3.0 / 1, 4.5 / 3, 7.0 / 45])
    # the mean of the ratios, not the ratio of the means: they differ where n is spread
    assert np.nanmean(got) != pytest.approx(e[2:].mean() / (n[2:].mean() * (n[2:].mean() - 1) / 2))
    with pytest.raises(RodwarpError, match="one shape"):
        pair_entanglement(e, n[:3])
