"""Garbage in and inputs accepted without a word (issue 29, classes 4 and 6).

Every bad input below goes through the real command line (:func:`rodwarp.cli.main`) and must
give exit code 2 and exactly one line on stderr that names the problem: no traceback, no
library advice (NumPy's "use pickle.load()"), no log lines of tifffile. The valid inputs next
to them still work where a check was added.
"""

from __future__ import annotations

import os
import zipfile

import numpy as np
import pytest
import tifffile

from rodwarp.cli import main
from rodwarp.rodset import RodSet

#: a tiny run: seconds on one core
TINY = ["--entangle-duration", "0.02", "--duration", "0.02", "--save-every", "0.01", "--device", "cpu",
        "--quiet"]
RANDOM = ["--alpha", "20", "--n-rods", "12", *TINY]


def refused(capsys, args, *fragments) -> str:
    """Run ``rodwarp ARGS``: exit 2, one non-empty stderr line holding every fragment."""
    capsys.readouterr()
    rc = main([str(a) for a in args])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert len(lines) == 1, err
    line = lines[0]
    assert line.startswith("error: "), line
    assert "Traceback" not in err and "pickle" not in err.lower(), line
    for f in fragments:
        assert f in line, line
    return line


# ----------------------------------------------------------------------------------------------
# rod sets
# ----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def polylines():
    """12 straight rods of length 1 m, diameter 0.05 m (alpha 20), apart from each other."""
    rng = np.random.default_rng(0)
    centres = np.c_[rng.uniform(0.2, 0.8, (12, 2)), np.linspace(0.1, 1.5, 12)]
    axes = rng.normal(size=(12, 3))
    axes[:, 2] = 0.0
    rods = RodSet.from_straight(centres, axes, 1.0, 0.025, n_vertices=4)
    return [rods.rod(i).copy() for i in range(rods.n_rods)]


def _save(path, polylines):
    RodSet.from_polylines(polylines, 0.025).save(path)
    return path


@pytest.fixture
def sets(tmp_path, polylines):
    """The valid set and its broken variants, each with rod 12 the bad one."""
    pl = polylines
    return {
        "good": _save(tmp_path / "good.npz", pl),
        "dup": _save(tmp_path / "dup.npz", pl + [pl[3].copy()]),
        "dup_reversed": _save(tmp_path / "duprev.npz", pl + [pl[3][::-1].copy()]),
        "zero": _save(tmp_path / "zero.npz", pl + [np.full((4, 3), 0.5)]),
        "far": _save(tmp_path / "far.npz", pl + [pl[0] + np.array([1e9, 0.0, 0.0])]),
    }


@pytest.mark.parametrize("name, fragments", [
    ("dup", ("rods 3 and 12", "duplicates", "remove")),
    ("dup_reversed", ("rods 3 and 12", "duplicates", "remove")),
    ("zero", ("rod 12 has zero length; remove it",)),
    ("far", ("rod 12 lies 1e+09 m", "remove rod 12")),
])
def test_analyze_refuses_bad_geometry(capsys, tmp_path, sets, name, fragments):
    out = tmp_path / "an"
    refused(capsys, ["analyze", sets[name], "--out", out, "--no-figures", "--quiet"], *fragments)
    assert not out.exists()


@pytest.mark.parametrize("name, fragments", [
    ("dup", ("--initial", "rods 3 and 12", "duplicates")),  # not "overlap by 1 d"
    ("dup_reversed", ("--initial", "rods 3 and 12", "duplicates")),
    ("zero", ("--initial", "rod 12 has zero length; remove it")),
    ("far", ("--initial", "rod 12 lies 1e+09 m", "1e+09 rod lengths")),
])
def test_simulate_initial_refuses_bad_geometry(capsys, tmp_path, sets, name, fragments):
    out = tmp_path / "sim"
    line = refused(capsys, ["simulate", "--initial", sets[name], "--out", out, *TINY], *fragments)
    assert "overlap" not in line
    assert not out.exists()


def test_phantom_refuses_duplicated_rods(capsys, tmp_path, sets):
    refused(capsys, ["phantom", sets["dup"], "--shape", "16", "16", "16", "--voxel-size", "0.1",
                     "--out", tmp_path / "p.tif"], "rods 3 and 12", "duplicates")


def test_valid_set_still_analyzed_and_simulated(capsys, tmp_path, sets):
    assert main(["analyze", str(sets["good"]), "--out", str(tmp_path / "an"), "--no-figures", "--quiet"]) == 0
    assert (tmp_path / "an" / "summary.json").exists()
    assert main(["simulate", "--initial", str(sets["good"]), "--out", str(tmp_path / "sim"), *TINY]) == 0
    assert (tmp_path / "sim" / "summary.json").exists()


def test_a_dilute_set_is_not_called_far(polylines):
    """Rods spread evenly over a wide box are not refused: only a stray rod is."""
    from rodwarp.rodset.sanity import check_rod_geometry

    rng = np.random.default_rng(1)
    spread = [p + rng.uniform(0, 300, 3) for p in polylines * 5]
    check_rod_geometry(RodSet.from_polylines(spread, 0.025), "dilute")


# ----------------------------------------------------------------------------------------------
# options accepted without a word
# ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("command", [
    ["simulate", *RANDOM],
    ["analyze", "IN"],
    ["phantom", "random", "--shape", "16", "16", "16"],
    ["segment", "IN"],
    ["sweep", "--alpha", "20"],
])
@pytest.mark.parametrize("form", ["separate", "equals"])
def test_empty_out_is_refused(capsys, tmp_path, sets, monkeypatch, command, form):
    monkeypatch.chdir(tmp_path)
    before = sorted(os.listdir(tmp_path))
    args = [str(sets["good"]) if a == "IN" else a for a in command]
    args += ["--out", ""] if form == "separate" else ["--out="]
    refused(capsys, args, "--out is empty")
    assert sorted(os.listdir(tmp_path)) == before  # nothing written into the current folder


@pytest.mark.parametrize("args, fragments", [
    (["--mu", "1e9"], ("--mu", "<= 10", "below about 2")),
    (["--checkpoint-every", "1e-6"], ("--checkpoint-every 1e-06 s", "2.6 times slower", "0.01")),
])
def test_simulate_option_bounds(capsys, tmp_path, args, fragments):
    refused(capsys, ["simulate", *RANDOM, *args, "--out", tmp_path / "o"], *fragments)
    assert not (tmp_path / "o").exists()


def test_entangle_with_zero_entangle_duration_is_a_contradiction(capsys, tmp_path, sets):
    refused(capsys, ["simulate", "--initial", sets["good"], "--entangle", *TINY, "--entangle-duration", "0",
                     "--out", tmp_path / "o"], "--entangle", "--entangle-duration 0")


def test_option_bounds_leave_valid_values(capsys, tmp_path):
    # mu at the bound and a checkpoint every sample (0.01 s) still run
    assert main(["simulate", *RANDOM, "--mu", "10", "--checkpoint-every", "0.01", "--out", str(tmp_path / "o")]) == 0


# ----------------------------------------------------------------------------------------------
# garbage rod-set files
# ----------------------------------------------------------------------------------------------

@pytest.fixture
def garbage(tmp_path):
    rnd = np.random.default_rng(3).bytes(4096)
    (tmp_path / "rand.npz").write_bytes(rnd)
    (tmp_path / "rand.csv").write_bytes(rnd)
    (tmp_path / "plain.zarr").write_bytes(rnd[:100])
    # a real zip holding an object array: NumPy would advise allow_pickle
    with zipfile.ZipFile(tmp_path / "objects.npz", "w") as z:
        import io

        buf = io.BytesIO()
        np.lib.format.write_array(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
        z.writestr("meta.npy", buf.getvalue())
    (tmp_path / "utf16.csv").write_bytes("rod,x,y,z,radius\n0,0,0,0,1\n".encode("utf-16"))
    return tmp_path


@pytest.mark.parametrize("name, fragments", [
    ("rand.npz", ("rand.npz is not a rod-set .npz", "not a readable zip/npz archive")),
    ("objects.npz", ("objects.npz is not a rod-set .npz", "object arrays")),
    ("rand.csv", ("rand.csv is not a text CSV", "binary")),
    ("utf16.csv", ("utf16.csv is UTF-16 text", "UTF-8")),
    ("plain.zarr", ("plain.zarr is a plain file, not a zarr store",)),
])
@pytest.mark.parametrize("command", ["analyze", "simulate"])
def test_garbage_rod_set_files(capsys, garbage, name, fragments, command):
    path = garbage / name
    out = garbage / "out"
    if command == "analyze":
        args = ["analyze", path, "--out", out, "--quiet"]
    else:
        args = ["simulate", "--initial", path, "--out", out, *TINY]
    line = refused(capsys, args, *fragments)
    assert "unsupported" not in line and "allow_pickle" not in line
    assert not out.exists()


# ----------------------------------------------------------------------------------------------
# garbage CT stacks
# ----------------------------------------------------------------------------------------------

def _segment(path, tmp_path):
    return ["segment", path, "--voxel-size", "1", "--units", "voxel", "--out", tmp_path / "seg", "--no-figures",
            "--quiet"]


@pytest.mark.parametrize("shape, kw", [
    ((64, 64, 3), {}),                                          # one RGB page: looked like a 64x64x3 volume
    ((3, 64, 64), {"planarconfig": "separate"}),                # planar RGB: looked like 3 slices
    ((64, 64, 4), {"extrasamples": ["unassalpha"]}),            # RGBA
    ((10, 64, 64, 3), {}),                                      # an RGB stack
])
def test_segment_refuses_rgb_tiffs(capsys, tmp_path, shape, kw):
    img = (np.random.default_rng(0).random(shape) * 255).astype(np.uint8)
    tifffile.imwrite(tmp_path / "rgb.tif", img, photometric="rgb", **kw)
    refused(capsys, _segment(tmp_path / "rgb.tif", tmp_path), "rgb.tif is an RGB image",
            "not a greyscale CT stack", "convert it to greyscale")
    assert not (tmp_path / "seg").exists()


def test_segment_refuses_an_rgb_slice_in_a_folder(capsys, tmp_path):
    folder = tmp_path / "slices"
    folder.mkdir()
    for k in range(3):
        tifffile.imwrite(folder / f"s{k}.tif", np.zeros((16, 16, 3), np.uint8), photometric="rgb")
    refused(capsys, _segment(folder, tmp_path), "s0.tif is an RGB image", "greyscale")


@pytest.mark.parametrize("compression", [None, "zlib"])
@pytest.mark.parametrize("keep", [0.02, 0.5, 0.99])
def test_segment_truncated_tiff_is_one_line(capsys, tmp_path, compression, keep):
    vol = (np.random.default_rng(0).random((20, 32, 32)) * 1000).astype(np.uint16)
    tifffile.imwrite(tmp_path / "full.tif", vol, compression=compression)
    data = (tmp_path / "full.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[:int(len(data) * keep)])
    line = refused(capsys, _segment(tmp_path / "cut.tif", tmp_path), "cut.tif is truncated or corrupt")
    assert "TiffPages" not in line


def test_segment_random_bytes_tiff(capsys, tmp_path):
    (tmp_path / "rand.tif").write_bytes(np.random.default_rng(1).bytes(5000))
    refused(capsys, _segment(tmp_path / "rand.tif", tmp_path), "rand.tif", "not a TIFF file")


@pytest.mark.parametrize("shape", [(2, 2, 2), (40, 40, 7)])
def test_segment_refuses_volumes_too_small_for_a_rod(capsys, tmp_path, shape):
    vol = (np.random.default_rng(0).random(shape) * 1000).astype(np.uint16)
    tifffile.imwrite(tmp_path / "small.tif", vol)
    refused(capsys, _segment(tmp_path / "small.tif", tmp_path), f"volume shape {shape} is too small to hold a rod",
            "at least 8 voxels")


def test_greyscale_tiffs_still_read(tmp_path):
    from rodwarp import ct

    vol = (np.random.default_rng(0).random((9, 12, 10)) * 1000).astype(np.uint16)
    for kw in ({}, {"compression": "zlib"}, {"photometric": "minisblack"}):
        tifffile.imwrite(tmp_path / "g.tif", vol, **kw)
        assert np.array_equal(ct.read_volume(tmp_path / "g.tif"), vol)
        assert np.array_equal(np.asarray(ct.open_volume_lazy(tmp_path / "g.tif")[...]), vol)
