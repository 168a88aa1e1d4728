"""Synthetic CT phantoms (rodwarp.ct) and CT volume I/O (rodwarp.ct)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import tifffile

from rodwarp import ct
from rodwarp.errors import RodwarpError
from rodwarp.rodset import RodSet, segment_distance

SHAPE = (64, 64, 64)


# ----------------------------------------------------------------------------------------------
# occupancy and rendering
# ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2])
def test_occupancy_sums_to_capsule_volume(seed):
    rods = ct.scene_isolated(SHAPE, radius=3, length=40, seed=seed)
    occ = ct.occupancy(rods, SHAPE)
    assert occ.dtype == np.float32 and occ.shape == SHAPE
    assert occ.min() >= 0 and occ.max() <= 1
    assert occ.sum() == pytest.approx(ct.capsule_volume(3, 40), rel=0.01)


def test_occupancy_of_union_counts_overlap_once():
    # two identical rods: the union has the volume of one
    one = RodSet.from_straight([[30.2, 31.7, 32.4]], [[1, 0.3, -0.2]], 36, 3.5, units="voxel")
    two = RodSet.from_polylines([one.rod(0), one.rod(0)[::-1]], 3.5, units="voxel")
    assert ct.occupancy(two, SHAPE).sum() == pytest.approx(ct.capsule_volume(3.5, 36), rel=0.01)


def test_coordinate_convention_x_is_column_z_is_slice():
    # a rod along x at row y = 20, slice z = 40: bright along volume[40, 20, :]
    rods = RodSet.from_straight([[32, 20, 40]], [[1, 0, 0]], 30, 3, units="voxel")
    occ = ct.occupancy(rods, SHAPE)
    assert occ[40, 20, 32] == 1 and occ[40, 20, 17:48].min() == 1
    assert occ[20, 40, 32] == 0
    zc, yc, xc = (np.array(np.nonzero(occ > 0.5)).mean(axis=1))
    assert (xc, yc, zc) == pytest.approx((32, 20, 40), abs=0.05)


def test_metric_rods_need_voxel_size_and_convert():
    rods_vox = ct.scene_isolated(SHAPE, seed=3)
    rods_mm = rods_vox.to_units("mm", voxel_size=20e-6)
    with pytest.raises(RodwarpError, match="voxel_size"):
        ct.occupancy(rods_mm, SHAPE)
    a = ct.occupancy(rods_vox, SHAPE)
    b = ct.occupancy(rods_mm, SHAPE, voxel_size=20e-6)
    assert np.abs(a - b).max() < 1e-5


def test_noiseless_blurred_phantom_axis_and_background():
    rods = RodSet.from_straight([[32, 32, 32]], [[1, 1, 0.5]], 40, 3, units="voxel")
    vol = ct.render_phantom(rods, SHAPE, blur_sigma=1.0, cnr=math.inf, background=8000, foreground=40000)
    assert vol.dtype == np.uint16 and vol.shape == SHAPE
    assert vol[32, 32, 32] == pytest.approx(40000, rel=0.02)
    assert vol[5, 5, 60] == 8000 and vol[60, 60, 5] == 8000


def test_noise_std_matches_contrast_over_cnr():
    rods = RodSet.from_straight([[32, 32, 32]], [[0, 0, 1]], 20, 3, units="voxel")
    vol = ct.render_phantom(rods, SHAPE, cnr=10.0, background=8000, foreground=40000, seed=5)
    empty = vol[:, :16, :16].astype(np.float64)  # far from the rod
    assert empty.std() == pytest.approx(3200, rel=0.05)
    assert empty.mean() == pytest.approx(8000, abs=50)


def test_render_is_deterministic_for_a_seed():
    rods = ct.scene_crossing_pair(SHAPE, 90)
    kw = dict(cnr=5.0, ring=0.1, cupping=0.1, streaks=0.2)
    a = ct.render_phantom(rods, SHAPE, seed=11, **kw)
    b = ct.render_phantom(rods, SHAPE, seed=11, **kw)
    c = ct.render_phantom(rods, SHAPE, seed=12, **kw)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_artefacts_change_the_image_as_described():
    rods = ct.scene_crossing_pair(SHAPE, 90)
    clean = ct.render_phantom(rods, SHAPE, cnr=math.inf).astype(np.float64)
    cup = ct.render_phantom(rods, SHAPE, cnr=math.inf, cupping=0.2).astype(np.float64)
    # cupping darkens the slice edge more than the centre; corners lose ~20%
    assert cup[2, 0, 0] == pytest.approx(0.8 * clean[2, 0, 0], rel=0.01)
    assert cup[2, 32, 32] > 0.99 * clean[2, 32, 32]
    ring = ct.render_phantom(rods, SHAPE, cnr=math.inf, ring=0.1).astype(np.float64)
    d = ring - clean
    assert np.abs(d).max() == pytest.approx(0.1 * (50000 - 20000), rel=0.05)  # default contrast
    assert np.allclose(d[3], d[60], atol=1)  # the same rings in every slice
    streak = ct.render_phantom(rods, SHAPE, cnr=math.inf, streaks=0.2).astype(np.float64)
    s = streak - clean
    assert s.max() > 0.02 * 30000 and s.min() < -0.1 * 30000  # bright and dark streaks


def test_render_rejects_bad_parameters():
    rods = ct.scene_isolated(SHAPE)
    with pytest.raises(RodwarpError):
        ct.render_phantom(rods, (64, 64), cnr=5)
    with pytest.raises(RodwarpError):
        ct.render_phantom(rods, SHAPE, cnr=0)
    with pytest.raises(RodwarpError):
        ct.render_phantom(rods, SHAPE, blur_sigma=-1)


# ----------------------------------------------------------------------------------------------
# scenes
# ----------------------------------------------------------------------------------------------

def _inside(rods, shape, margin=0.0):
    bb = rods.bounding_box()
    return np.all(bb[0] >= -0.5 + margin - 1e-9) and np.all(bb[1] <= np.array(shape[::-1]) - 0.5 - margin + 1e-9)


def test_scene_isolated_inside_with_margin():
    for seed in range(5):
        rods = ct.scene_isolated(SHAPE, radius=3, seed=seed)
        assert rods.n_rods == 1 and rods.units == "voxel" and len(rods.contacts) == 0
        assert _inside(rods, SHAPE, margin=2.0)


@pytest.mark.parametrize("angle", [90.0, 30.0])
def test_scene_crossing_pair_touching_has_one_contact(angle):
    rods = ct.scene_crossing_pair(SHAPE, angle)
    assert rods.n_rods == 2 and _inside(rods, SHAPE, margin=2.0)
    c = rods.contacts
    assert len(c) == 1 and abs(c.gap[0]) < 1e-9
    d = [rods.rod(i)[-1] - rods.rod(i)[0] for i in range(2)]
    cosang = abs(d[0] @ d[1]) / np.linalg.norm(d[0]) / np.linalg.norm(d[1])
    assert math.degrees(math.acos(cosang)) == pytest.approx(angle, abs=1e-6)


def test_scene_pairs_gap_two_has_no_contact():
    near = ct.scene_crossing_pair(SHAPE, 90, gap=2.0)
    assert len(near.contacts) == 0
    p = near.points
    assert float(segment_distance(p[0], p[1], p[2], p[3])) - 6 == pytest.approx(2.0, abs=1e-9)
    assert len(ct.scene_parallel_pair(SHAPE, gap=2.0).contacts) == 0
    par = ct.scene_parallel_pair(SHAPE, seed=4)
    assert len(par.contacts) == 1 and abs(par.contacts.gap[0]) < 1e-9 and _inside(par, SHAPE, 2.0)
    rot = ct.scene_crossing_pair(SHAPE, 30, seed=7)
    assert len(rot.contacts) == 1 and _inside(rot, SHAPE, 2.0)


def test_scene_random_packing_contract():
    shape = (96, 96, 96)
    rods = ct.scene_random_packing(shape, n_rods=40, radius=3, aspect=8, touching_fraction=0.5, seed=1)
    assert rods.n_rods == 40 and rods.units == "voxel"
    assert np.allclose(rods.rod_lengths(), 48)
    assert _inside(rods, shape, margin=2.0)
    p0, p1, _ = rods.segments()
    i, j = np.triu_indices(rods.n_rods, 1)
    gaps = segment_distance(p0[i], p1[i], p0[j], p1[j]) - 6.0
    assert gaps.min() > -1e-9  # no overlaps
    assert np.all((np.abs(gaps) < 1e-9) | (gaps >= 2.0 - 1e-9))  # touching or clearly apart
    touching = np.zeros(rods.n_rods, bool)
    touching[rods.contacts.rod_i] = touching[rods.contacts.rod_j] = True
    assert len(rods.contacts) == int(np.sum(np.abs(gaps) < 1e-9))
    assert 0.35 <= touching.mean() <= 0.65
    again = ct.scene_random_packing(shape, n_rods=40, radius=3, aspect=8, seed=1)
    assert np.array_equal(again.points, rods.points)


def test_scene_random_packing_too_crowded_is_an_error():
    with pytest.raises(RodwarpError, match="could only place"):
        ct.scene_random_packing((32, 32, 32), n_rods=50, radius=3, aspect=3, max_attempts=640)


def test_phantom_truth_tolerance_and_units():
    rods = ct.scene_crossing_pair(SHAPE, 90, gap=0.3)
    assert len(ct.phantom_truth(rods, 0.5)) == 1
    assert len(ct.phantom_truth(rods, 0.2)) == 0
    mm = rods.to_units("mm", voxel_size=10e-6)
    c = ct.phantom_truth(mm, 0.5, voxel_size=10e-6)
    assert len(c) == 1 and c.gap[0] == pytest.approx(0.3 * 0.01)


def test_write_phantom_writes_tiff_and_truth(tmp_path):
    rods = ct.scene_crossing_pair(SHAPE, 90)
    params = dict(blur_sigma=1.0, cnr=5.0, seed=3)
    vol = ct.render_phantom(rods, SHAPE, **params)
    out = ct.write_phantom(tmp_path / "stack.tif", vol, rods, rods.contacts, 15e-6, params)
    assert np.array_equal(ct.read_volume(out["tiff"]), vol)
    truth = RodSet.load(tmp_path / "stack_truth.npz")
    assert truth.units == "voxel" and np.allclose(truth.points, rods.points) and len(truth.contacts) == 1
    meta = json.loads((tmp_path / "stack_truth.json").read_text())
    assert meta["voxel_size"] == 15e-6 and meta["seed"] == 3 and meta["params"]["cnr"] == 5.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stack.tif", "stack_truth.json", "stack_truth.npz"]


# ----------------------------------------------------------------------------------------------
# ctio
# ----------------------------------------------------------------------------------------------

@pytest.fixture
def volume():
    return (np.random.default_rng(0).random((6, 9, 11)) * 60000).astype(np.uint16)


def test_tiff_folder_and_zarr_reads_agree(tmp_path, volume):
    import zarr

    ct.write_tiff(tmp_path / "v.tif", volume, voxel_size=1e-5)
    with tifffile.TiffFile(tmp_path / "v.tif") as tf:
        assert tf.is_imagej and tf.series[0].axes == "ZYX"
    folder = tmp_path / "slices"
    folder.mkdir()
    for k in range(volume.shape[0]):  # names that sort wrongly as text: s0, s2, s4, s6, s8, s10
        tifffile.imwrite(folder / f"s{2 * k}.tif", volume[k])
    zarr.save_array(str(tmp_path / "v.zarr"), volume)
    g = zarr.open_group(str(tmp_path / "g.zarr"), mode="w")
    g.create_array("volume", data=volume)
    for src in ("v.tif", "slices", "v.zarr", "g.zarr"):
        got = ct.read_volume(tmp_path / src)
        assert got.dtype == volume.dtype and np.array_equal(got, volume), src
        lazy = ct.open_volume_lazy(tmp_path / src)
        assert tuple(lazy.shape) == volume.shape and lazy.dtype == volume.dtype
        assert np.array_equal(np.asarray(lazy[2:5, 1:7]), volume[2:5, 1:7]), src


def test_ctio_errors(tmp_path, volume):
    def err(path, match):
        with pytest.raises(RodwarpError, match=match) as e:
            ct.read_volume(path)
        assert "\n" not in str(e.value)

    tifffile.imwrite(tmp_path / "flat.tif", volume[0])
    err(tmp_path / "flat.tif", "is 2-D; a CT stack needs several slices".replace("; ", ".*"))
    tifffile.imwrite(tmp_path / "const.tif", np.full((4, 5, 5), 123, np.uint16))
    err(tmp_path / "const.tif", "constant volume: no contrast to segment")
    tifffile.imwrite(tmp_path / "empty.tif", np.zeros((0, 5, 5), np.uint16))
    err(tmp_path / "empty.tif", "empty")
    err(tmp_path / "missing.tif", "does not exist")
    (tmp_path / "junk.tif").write_bytes(b"not a tiff")
    err(tmp_path / "junk.tif", "cannot read")
    nan = volume.astype(np.float32)
    nan[1, 2, 3] = np.nan
    tifffile.imwrite(tmp_path / "nan.tif", nan)
    err(tmp_path / "nan.tif", "NaN")
    folder = tmp_path / "slices"
    folder.mkdir()
    for k in range(3):
        tifffile.imwrite(folder / f"slice_{k:03d}.tif", volume[k])
    tifffile.imwrite(folder / "slice_003.tif", volume[0, :5])
    err(folder, "slice_003.tif")
