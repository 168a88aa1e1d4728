"""Segmentation of realistic scans (rodwarp.ct): field-of-view masks, cupping, rings,
anisotropic voxels, mixed radii, bundles, thin and faint rods, dark rods, arcs and wire tangles.

Every case is a phantom with ground truth; the targets are those of the realistic-scan work:
straight rods F1 >= 0.95 and contact recall >= 0.9; curved filaments matched as polylines.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from typer.testing import CliRunner

from rodwarp import ct
from rodwarp.cli import app
from rodwarp.ct import (SegmentParams, make_case, match_polylines, match_rods, parse_voxel_size, prepare_volume,
                        score_contacts, scored_subset, segment_volume)
from rodwarp.errors import RodwarpError
from rodwarp.rodset import load as load_rods

runner = CliRunner()


def _score(case, res):
    shape_xyz = np.asarray(case.volume.shape[::-1], float) * np.asarray(case.voxel_size[::-1], float)
    found, con = scored_subset(res.rods, res.contacts, shape_xyz, case.face_margin)
    truth, tc = scored_subset(case.truth, case.truth.contacts, shape_xyz, case.face_margin)
    truth.contacts = tc
    m = match_polylines(found, truth) if case.curved else match_rods(found, truth)
    return m, score_contacts(con, truth, m)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cnr2", "faces", "fov", "cupping", "cupping_rings", "mixed_radii", "thin",
                                  "thin_faint", "anisotropic", "dark"])
def test_straight_rod_scans_meet_targets(name):
    case = make_case(name, 0)
    res = segment_volume(case.volume, voxel_size=case.voxel_size)
    m, cs = _score(case, res)
    assert res.quality["shape"] == "straight"
    assert m.f1 >= 0.95, (name, m.f1)
    assert cs.recall >= 0.9, (name, cs.recall)
    assert np.mean(m.mean_distance) <= 0.5
    if name == "mixed_radii":
        # every rod carries its own radius, within 0.3 voxel of the truth
        assert res.quality["per_rod_radius"]
        err = np.abs(res.rods.radii[m.pairs[:, 0]] - case.truth.radii[m.pairs[:, 1]])
        assert np.median(err) <= 0.15 and err.max() <= 0.5
    if name == "fov":
        assert res.quality["fov"] is not None and abs(res.quality["fov"]["radius"] - 76) < 2
    if name in ("cupping", "cupping_rings"):
        assert res.quality["background_trend"] is not None
    if name == "dark":
        assert res.quality["dark_rods"]
    if name == "anisotropic":
        assert res.spacing == 1.0 and res.quality["zoom"] == [2.0, 1.0, 1.0]


@pytest.mark.slow
def test_bundles_of_touching_rods_are_split():
    # measured: F1 0.933 (seed 0, contact recall 0.82), 0.964 (seed 1, 0.79); over the 10 seeds
    # the benchmark draws F1 median 0.98 and contact recall 0.93, worst 0.89 / 0.60 (a ghost line
    # along a bundle's middle costs its rods); before the bundle fit: F1 0.25
    case = make_case("bundles", 0)
    res = segment_volume(case.volume)
    m, cs = _score(case, res)
    assert res.quality.get("bundles_split", 0) >= 5
    # no ghost rods along the bundles' middles: every rod found is a true rod
    assert m.precision >= 0.97
    assert m.f1 >= 0.9, m.f1
    assert cs.recall >= 0.75, cs.recall
    assert abs(np.median(res.rods.radii) - 3.0) <= 0.5  # (3.38: the partition between touching rods leaks)


_CURVED: dict = {}


def _curved(name):
    """One segmentation per curved case, shared by the tests that read it."""
    if name not in _CURVED:
        case = make_case(name, 0)
        _CURVED[name] = (case, segment_volume(case.volume))
    return _CURVED[name]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["arcs", "wires"])
def test_curved_filaments_as_polylines(name):
    case, res = _curved(name)
    assert res.quality["shape"] == "curved"  # shape="auto" recognised the bends
    m, _ = _score(case, res)
    # arcs: every seed 1.00; wire tangles: 1.00 on seeds 0-2, median 0.99 and worst 0.80 over 16
    # development seeds (benchmarks/RESULTS.md, segment_scans: the 10 drawn seeds)
    assert m.f1 >= (0.95 if name == "arcs" else 0.9), (name, m.f1)
    assert np.mean(m.mean_distance) <= 1.0
    assert res.rods.vertex_counts.min() >= 3  # polylines, not chords
    # contacts join distinct filaments only: the two filaments of a contact match different wires
    mp = m.mapping()
    for a, b in zip(res.contacts.rod_i, res.contacts.rod_j):
        assert a != b
        if a in mp and b in mp:
            assert mp[a] != mp[b]


@pytest.mark.slow
def test_wire_tangles_over_three_seeds():
    f1 = []
    for seed in (1, 2):
        case = make_case("wires", seed)
        f1.append(_score(case, segment_volume(case.volume))[0].f1)
    f1.append(_score(*_curved("wires"))[0].f1)
    # 1.00 on each today; the greedy bridges before the matching gave 0.83-0.86
    assert min(f1) >= 0.9, f1


def test_straight_mode_on_arcs_gives_chords_auto_gives_curves():
    case = make_case("arcs", 0)
    straight = segment_volume(case.volume, SegmentParams(shape="straight"))
    assert straight.rods.vertex_counts.max() == 2
    assert any("bends" in f for f in straight.quality["flags"])  # the warning names the cause
    ms = match_polylines(straight.rods, case.truth)
    assert ms.f1 < 0.9


@pytest.mark.slow
def test_analyze_of_segmented_filaments_gives_the_truths_cv_e(tmp_path):
    from rodwarp.analysis import AnalyzeOptions, analyze

    case, res = _curved("wires")
    seg = res.rods.copy()
    seg.contacts = res.contacts
    truth = case.truth.copy()
    lo, hi = np.zeros(3) - 0.5, np.asarray(case.volume.shape[::-1], float) - 0.5
    for r in (seg, truth):
        r.box = np.stack([lo, hi])
    a = tmp_path / "seg.npz"
    b = tmp_path / "truth.npz"
    seg.save(a)
    truth.save(b)
    # one ball radius for both (the truth's default), so the fields are comparable
    d = 2.0 * float(np.mean(truth.radii))
    R = float(np.sqrt(d * np.mean(truth.rod_lengths())))
    opts = AnalyzeOptions(radius=R, figures=False)
    sa = analyze(a, tmp_path / "a_seg", opts, progress=False)
    sb = analyze(b, tmp_path / "a_truth", opts, progress=False)
    assert sb["cv_e"] > 0
    assert abs(sa["cv_e"] - sb["cv_e"]) <= 0.05 * sb["cv_e"], (sa["cv_e"], sb["cv_e"])


# ----------------------------------------------------------------------------------------------
# preparation, metadata, command line
# ----------------------------------------------------------------------------------------------

def test_clean_scan_passes_preparation_unchanged():
    case = make_case("baseline", 0)
    prep = prepare_volume(case.volume)
    assert prep.volume is case.volume
    assert prep.fov is None and prep.trend is None and not prep.dark


@pytest.mark.parametrize("text,msg", [((1.0, 2.0), "one value"), ((0.1, -1, 1), "positive"),
                                      (("a",), "numbers")])
def test_bad_voxel_sizes(text, msg):
    with pytest.raises(RodwarpError, match=msg):
        parse_voxel_size(text)


def test_voxel_size_from_imagej_ome_and_zarr_metadata(tmp_path):
    v = np.zeros((4, 8, 8), np.uint16)
    ct.write_tiff(tmp_path / "a.tif", v, voxel_size=(2e-5, 1e-5, 1e-5))
    sizes, src = ct.read_voxel_size(tmp_path / "a.tif")
    assert np.allclose(sizes, (2e-5, 1e-5, 1e-5)) and "ImageJ" in src
    tifffile.imwrite(tmp_path / "b.ome.tif", v, metadata={
        "axes": "ZYX", "PhysicalSizeX": 0.05, "PhysicalSizeY": 0.05, "PhysicalSizeZ": 0.1,
        "PhysicalSizeXUnit": "mm", "PhysicalSizeYUnit": "mm", "PhysicalSizeZUnit": "mm"})
    sizes, src = ct.read_voxel_size(tmp_path / "b.ome.tif")
    assert np.allclose(sizes, (1e-4, 5e-5, 5e-5)) and "OME" in src
    tifffile.imwrite(tmp_path / "c.tif", v, photometric="minisblack")
    assert ct.read_voxel_size(tmp_path / "c.tif") is None
    import zarr

    g = zarr.open_group(str(tmp_path / "o.zarr"), mode="w")
    g.create_array("0", shape=(4, 8, 8), dtype="u2")
    g.attrs["multiscales"] = [{"axes": [{"name": a, "type": "space", "unit": "micrometer"} for a in "zyx"],
                               "datasets": [{"path": "0", "coordinateTransformations": [
                                   {"type": "scale", "scale": [3.0, 1.5, 1.5]}]}]}]
    sizes, src = ct.read_voxel_size(tmp_path / "o.zarr")
    assert np.allclose(sizes, (3e-6, 1.5e-6, 1.5e-6)) and "OME-Zarr" in src


def test_cli_anisotropic_phantom_segments_from_its_metadata(tmp_path):
    tif = tmp_path / "aniso.tif"
    res = runner.invoke(app, ["phantom", "random", "--shape", "48", "96", "96", "--z-thickness", "2", "--n-rods",
                              "10", "--aspect", "10", "--cnr", "6", "--seed", "2", "--out", str(tif)])
    assert res.exit_code == 0, res.output
    out = tmp_path / "seg"
    res = runner.invoke(app, ["segment", str(tif), "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    # a scene has no physical scale: the TIFF says so, and lengths come out in voxel widths
    assert s["voxel_size_zyx"] == pytest.approx([2.0, 1.0, 1.0]) and s["units"] == "voxel"
    truth = load_rods(tmp_path / "aniso_truth.npz")
    rods = load_rods(out / "rods.npz")
    assert rods.units == "voxel"
    m = match_rods(rods, truth)
    assert m.f1 == 1.0 and np.max(m.mean_distance) < 0.5


def test_cli_curved_phantom_and_flags(tmp_path):
    tif = tmp_path / "w.tif"
    res = runner.invoke(app, ["phantom", "arcs", "--shape", "96", "96", "96", "--n-rods", "6", "--seed", "1",
                              "--out", str(tif)])
    assert res.exit_code == 0, res.output
    truth = load_rods(tmp_path / "w_truth.npz")
    assert truth.n_rods == 6 and truth.vertex_counts.min() > 2
    res = runner.invoke(app, ["segment", str(tif), "--shape", "curved", "--out", str(tmp_path / "s"), "--quiet"])
    assert res.exit_code == 0, res.output
    assert "filaments" in res.output
    rods = load_rods(tmp_path / "s" / "rods.npz")
    assert rods.units == "voxel"
    m = match_polylines(rods, truth)
    assert m.f1 == 1.0


@pytest.mark.parametrize("args,fragment", [
    (["--voxel-size", "0.1,0.2"], "one value"),
    (["--voxel-size", "0.1,x,0.2"], "voxel-size"),
    (["--shape", "wiggly"], "shape"),
    ([], "records no voxel size"),
])
def test_segment_cli_bad_voxel_size_and_shape(args, fragment, tmp_path):
    p = tmp_path / "x.tif"
    tifffile.imwrite(p, np.random.default_rng(0).integers(0, 60000, (16, 32, 32), dtype=np.uint16))
    res = runner.invoke(app, ["segment", str(p), *args, "--out", str(tmp_path / "o"), "--quiet"])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip() and "CUDA" not in ln]
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    assert fragment.lower() in lines[0].lower()


def test_phantom_options_fov_dark_anisotropic():
    rods = ct.scene_random_packing((40, 64, 64), n_rods=4, radius=3.0, aspect=5.0, seed=1, fov_radius=28.0)
    vol = ct.render_phantom(rods, (20, 64, 64), cnr=None, fov=30.0, z_thickness=2, background=50000,
                            foreground=20000)
    assert vol.shape == (20, 64, 64)
    assert vol[10, 0, 0] == 0 and vol[10, 32, 32] != 0  # outside the field of view: 0
    assert vol[:, 20:44, 20:44].min() < 45000  # dark rods
    with pytest.raises(RodwarpError, match="z_thickness"):
        ct.render_phantom(rods, (20, 64, 64), z_thickness=0)


@pytest.mark.slow
def test_bundles_with_an_inflated_coarse_radius_keep_touching_rods_apart():
    # a seed the benchmark draws (SEED_DRAW 33): the bundles make the coarse radius 5.3 voxels
    # against 3.3 fitted; moved with the coarse one, touching rods shared one window and pulled
    # together (F1 0.78, contact recall 0.46); the first round is now redone with the fitted radius
    case = make_case("bundles", 1887504395)
    res = segment_volume(case.volume)
    m, cs = _score(case, res)
    assert res.quality["coarse_radius"] > 1.4 * float(np.median(res.rods.radii))
    assert m.f1 >= 0.85, m.f1
    assert cs.recall >= 0.55, cs.recall
