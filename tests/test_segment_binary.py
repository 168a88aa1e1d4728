"""Binarised CT stacks (two grey levels): recognised, segmented from the mask, or refused."""

import json

import numpy as np
import pytest
import tifffile
from typer.testing import CliRunner

from rodwarp import ct
from rodwarp.ct import SegmentParams, match_rods, score_contacts, segment_volume
from rodwarp.ct.segment._binary import MAX_LABEL_LEVELS, SurfaceDistance, read_binarised, surface_radius
from rodwarp.ct.segment._segment import _flags
from rodwarp.cli import app
from rodwarp.errors import RodwarpError
from rodwarp.testing.binarised import ENCODINGS
from rodwarp.testing.binarised import LEVELS as ENCODING_LEVELS

runner = CliRunner()

#: the phantoms' grey levels (``render_phantom`` defaults): the half level cuts a rod at the
#: surface its blurred profile crosses half-way
BACKGROUND, FOREGROUND = 20000.0, 50000.0
HALF = 0.5 * (BACKGROUND + FOREGROUND)

#: the two-level encodings a binarised stack is shared in: mask -> stack, and their levels
VARIANTS, LEVELS = ENCODINGS, ENCODING_LEVELS


def _phantom(shape, n_rods, seed, blur=1.0, touching=0.5, radius=2.5, aspect=8.0):
    truth = ct.scene_random_packing(shape, n_rods=n_rods, radius=radius, aspect=aspect,
                                    touching_fraction=touching, seed=seed)
    vol = ct.render_phantom(truth, shape, blur_sigma=blur, cnr=12.0, seed=seed)
    return truth, vol


@pytest.fixture(scope="module")
def four():
    """The 4-rod phantom of the issue (48^3, radius 2.5, one contact) and its mask."""
    truth, vol = _phantom((48, 48, 48), 4, 0)
    return truth, vol, vol > HALF


@pytest.fixture(scope="module")
def dense():
    """20 rods in 64^3, most of them touching (7 contacts), and the mask."""
    truth, vol = _phantom((64, 64, 64), 20, 2, touching=0.6)
    return truth, vol, vol > HALF


def _scores(res, truth):
    m = match_rods(res.rods, truth)
    cs = score_contacts(res.contacts, truth, m)
    rel = res.rods.radii[m.pairs[:, 0]] / truth.radii[m.pairs[:, 1]] - 1.0
    return m, cs, rel


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_four_rods_from_every_two_level_encoding(variant, four):
    truth, _, mask = four
    res = segment_volume(VARIANTS[variant](mask))
    m, cs, rel = _scores(res, truth)
    assert m.f1 >= 0.95 and res.rods.n_rods == truth.n_rods, (variant, m.f1, res.rods.n_rods)
    assert cs.tp == len(truth.contacts) and cs.fp == 0, (variant, cs)
    # the half-level mask of a blurred rod is a little thinner than the rod (measured -7%)
    assert np.all(np.abs(rel) <= 0.15), (variant, rel)
    b = res.quality["binarised"]
    assert b["levels"] == LEVELS[variant] and b["rod_level"] == LEVELS[variant][1]
    assert res.quality["fov"] is None and res.quality["background_trend"] is None
    assert res.quality["radius_profile_fit"] is None  # no blurred-profile fit on a mask


@pytest.mark.parametrize("variant", ["bool", "uint8 0/255", "uint16 100/3000"])
def test_dense_touching_rods_and_their_contacts(variant, dense):
    truth, _, mask = dense
    res = segment_volume(VARIANTS[variant](mask))
    m, cs, rel = _scores(res, truth)
    assert m.f1 >= 0.95, m.f1
    assert cs.recall >= 0.9 and cs.precision >= 0.9, cs
    assert np.all(np.abs(rel) <= 0.15), rel


def test_grey_scan_is_not_binarised_and_the_mask_finds_its_rods(dense):
    truth, vol, mask = dense
    grey = segment_volume(vol)
    assert grey.quality["binarised"] is None and grey.quality["radius_profile_fit"] is not None
    binary = segment_volume(mask)
    m = match_rods(binary.rods, grey.rods, max_mean_distance=0.5, max_angle_deg=2.0)
    assert m.f1 == 1.0, m.f1


def test_radii_of_digitised_cylinders_from_the_distance_transform():
    # no blur: the half-level mask is the digitised rods, so the radius must be the rods' own
    truth, vol = _phantom((64, 64, 64), 12, 5, blur=0.0, radius=3.0, aspect=6.0)
    res = segment_volume(vol > HALF)
    m, _, rel = _scores(res, truth)
    assert m.f1 >= 0.95
    assert np.all(np.abs(rel) <= 0.03), rel


def test_surface_radius_of_a_cylinder_along_a_diagonal():
    n, r = 40, 4.0
    z, y, x = np.indices((n, n, n)).astype(float)
    u = np.array([1.0, 2.0, 2.0]) / 3.0
    p = np.stack([x, y, z], -1) - (n - 1) / 2.0 - 0.3
    t = p @ u
    rho = np.linalg.norm(p - t[..., None] * u, axis=-1)
    mask = (rho < r).astype(np.float32)
    phi = SurfaceDistance(mask)[:, :, :]
    mid = np.abs(t) < 8
    assert surface_radius(phi[mid], rho[mid]) == pytest.approx(r, abs=0.05)
    # a block read with its halo gives the same distances as the whole volume
    np.testing.assert_array_equal(SurfaceDistance(mask)[10:20, 5:30, 12:13], phi[10:20, 5:30, 12:13])


def test_dark_rods_are_the_lower_level(four):
    truth, _, mask = four
    inverted = (~mask).astype(np.uint8)
    res = segment_volume(inverted, SegmentParams(dark=True))
    m, cs, _ = _scores(res, truth)
    assert m.f1 >= 0.95 and res.quality["binarised"]["rod_level"] == 0 and res.quality["dark_rods"]
    with pytest.raises(RodwarpError, match="--dark-rods"):  # the brighter level fills the volume
        segment_volume(inverted)


def test_anisotropic_binarised_stack(dense):
    truth, _, mask = dense
    res = segment_volume(mask[::2].astype(np.uint8), voxel_size=(2.0, 1.0, 1.0))
    m, cs, rel = _scores(res, truth)
    assert res.quality["zoom"] == [2.0, 1.0, 1.0]
    assert m.f1 >= 0.95 and cs.recall >= 0.9
    # through the signed distance; resampling the mask itself cut at 0.5 lost a fifth of it
    assert np.all(np.abs(rel) <= 0.15), rel


class _Lazy:
    """An array-like read by slicing only (a zarr array, a slice stack)."""

    def __init__(self, a):
        self.a, self.shape, self.dtype = a, a.shape, a.dtype

    def __getitem__(self, idx):
        return self.a[idx]


def test_lazy_chunked_binarised_stack_gives_the_same_rods(four):
    _, _, mask = four
    stack = (mask * 255).astype(np.uint8)
    ref = segment_volume(stack)
    res = segment_volume(_Lazy(stack), SegmentParams(chunk=24))
    assert res.quality["binarised"] == ref.quality["binarised"]
    m = match_rods(res.rods, ref.rods, max_mean_distance=0.2, max_angle_deg=1.0)
    assert m.f1 == 1.0 and len(res.contacts) == len(ref.contacts)
    np.testing.assert_allclose(res.rods.radii, ref.rods.radii, atol=0.02)


@pytest.mark.parametrize("n_levels", [3, 5, MAX_LABEL_LEVELS])
def test_label_images_are_refused(n_levels):
    labels = np.arange(32 * 32 * 32).reshape(32, 32, 32) % n_levels
    with pytest.raises(RodwarpError, match=f"only {n_levels} distinct values") as e:
        segment_volume(labels.astype(np.uint8))
    assert "label image" in str(e.value) and "\n" not in str(e.value)


def test_nine_levels_are_grey():
    vol = np.random.default_rng(0).integers(0, MAX_LABEL_LEVELS + 1, (16, 16, 16)).astype(np.uint8)
    assert read_binarised(vol) is None


def test_flag_when_the_rods_level_is_most_of_the_volume():
    q = {"binarised": {"levels": [0, 1], "rod_level": 1, "rod_fraction": 0.7}}
    assert any("--dark-rods" in f for f in _flags(q, "straight"))
    q["binarised"]["rod_fraction"] = 0.2
    assert _flags(q, "straight") == []


# ----------------------------------------------------------------------------------------------
# the command line
# ----------------------------------------------------------------------------------------------

def _segment(tmp_path, stack, *args):
    p = tmp_path / "stack.tif"
    tifffile.imwrite(p, stack)
    out = tmp_path / "seg"
    res = runner.invoke(app, ["segment", str(p), "--voxel-size", "1", "--units", "voxel", "--out", str(out),
                              "--quiet", "--no-figures", *args])
    return res, out


@pytest.mark.parametrize("variant", ["bool", "uint8 0/255"])
def test_cli_says_binarised(variant, four, tmp_path):
    truth, _, mask = four
    res, out = _segment(tmp_path, VARIANTS[variant](mask))
    assert res.exit_code == 0, res.output
    lo, hi = LEVELS[variant]
    assert f"4 rods, 1 contacts" in res.output and f"binarised stack (levels {lo}/{hi}, rods {hi})" in res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["binarised"] is True and s["quality"]["binarised"]["levels"] == [lo, hi]
    assert s["n_rods"] == 4 and s["n_contacts"] == 1


def _lines(res):
    return [ln for ln in res.output.strip().splitlines() if ln.strip() and "CUDA" not in ln]


@pytest.mark.parametrize("make, args, fragment", [
    ("constant", [], "volume is constant"),
    ("labels", [], "label image"),
    ("speck", [], "holds only 8 voxels"),
    ("inverted", [], "pass --dark-rods"),
    ("empty dark", ["--dark-rods"], "pass --bright-rods"),
])
def test_cli_refusals_are_one_line(make, args, fragment, tmp_path):
    if make == "constant":
        stack = np.full((16, 32, 32), 255, np.uint8)
    elif make == "labels":  # four phases, as a label image holds them
        stack = (np.indices((24, 24, 24)).sum(0) // 18).astype(np.uint8)
    elif make == "speck":  # a 2 x 2 x 2 foreground: no rod
        stack = np.pad(np.ones((2, 2, 2), np.uint8), 15)
    elif make == "inverted":  # rods 0 on a background of 1, read the default way round
        stack = np.pad(np.zeros((4, 4, 40), np.uint8), 12, constant_values=1)
    else:  # --dark-rods on a mask whose lower level is almost everything
        stack = np.pad(np.ones((4, 4, 40), np.uint8), 12)
    res, out = _segment(tmp_path, stack, *args)
    assert res.exit_code == 2, res.output
    lines = _lines(res)
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    assert fragment in lines[0], lines[0]
