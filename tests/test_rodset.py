"""RodSet: construction, validation, geometry, unit conversion and file round trips (no warp)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from rodwarp.errors import RodwarpError
from rodwarp.rodset import FORMAT_VERSION, Contacts, RodSet, load


def one_line_error(fn, *args, match: str | None = None, **kw) -> str:
    with pytest.raises(RodwarpError) as info:
        fn(*args, **kw)
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert msg.strip(), "empty message"
    if match is not None:
        assert match in msg, msg
    return msg


@pytest.fixture
def ragged() -> RodSet:
    """Three rods with 2, 3 and 10 vertices, plus every optional field."""
    rng = np.random.default_rng(7)
    polys = [rng.normal(size=(n, 3)) for n in (2, 3, 10)]
    V = 15
    contacts = Contacts(np.array([2, 0]), np.array([1, 2]), rng.normal(size=(2, 3)), np.array([-1e-4, 0.3]))
    return RodSet.from_polylines(
        polys, np.array([0.01, 0.02, 0.0125]), units="mm",
        rest_points=rng.normal(size=(V, 3)), velocities=rng.normal(size=(V, 3)), contacts=contacts,
        box=np.array([[-5.0, -5.0, -5.0], [5.0, 5.0, 7.5]]),
        attrs={"seed": 42, "params": {"mu": 0.3, "name": "test"}, "tags": [1, 2.5, "x"]})


def assert_same(a: RodSet, b: RodSet, *, full: bool = True) -> None:
    assert np.array_equal(a.points, b.points)
    assert np.array_equal(a.offsets, b.offsets)
    assert np.array_equal(a.radii, b.radii)
    assert a.points.dtype == b.points.dtype == np.float64
    assert a.offsets.dtype == b.offsets.dtype == np.int64
    if not full:
        return
    assert a.units == b.units
    assert a.attrs == b.attrs
    for name in ("rest_points", "velocities", "box"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert np.array_equal(x, y), name
    assert (a.contacts is None) == (b.contacts is None)
    if a.contacts is not None:
        for name in ("rod_i", "rod_j", "point", "gap"):
            assert np.array_equal(getattr(a.contacts, name), getattr(b.contacts, name)), name


# -- round trips -------------------------------------------------------------------------------

@pytest.mark.parametrize("suffix", [".npz", ".zarr"])
def test_round_trip_full(tmp_path, ragged, suffix):
    path = ragged.save(tmp_path / f"rods{suffix}")
    back = load(path)
    assert_same(ragged, back)
    assert_same(ragged, RodSet.load(path))
    assert back.contacts.rod_i.dtype == np.int64


@pytest.mark.parametrize("suffix", [".npz", ".zarr"])
def test_round_trip_minimal_and_empty_contacts(tmp_path, suffix):
    rods = RodSet.from_polylines([[[0, 0, 0], [1, 0, 0]]], 0.1)
    back = load(rods.save(tmp_path / f"a{suffix}"))
    assert_same(rods, back)
    assert back.contacts is None and back.box is None and back.rest_points is None
    rods.contacts = Contacts.empty()
    back = load(rods.save(tmp_path / f"b{suffix}"))
    assert back.contacts is not None and len(back.contacts) == 0
    assert back.contacts.point.shape == (0, 3)


def test_round_trip_csv(tmp_path, ragged):
    path = ragged.save(tmp_path / "rods.csv")
    header = path.read_text().splitlines()[0]
    assert header == "rod,x,y,z,radius"
    back = load(path, units="mm")
    assert_same(ragged, back, full=False)
    assert back.units == "mm"
    assert load(path).units == "m"  # the CSV records no unit


def test_overwrite_and_no_temp_files(tmp_path, ragged):
    for name in ("r.npz", "r.zarr", "r.csv"):
        ragged.save(tmp_path / name)
        ragged.save(tmp_path / name)  # replacing an existing file / directory
    assert sorted(os.listdir(tmp_path)) == ["r.csv", "r.npz", "r.zarr"]
    assert_same(ragged, load(tmp_path / "r.zarr"))


def test_failed_write_leaves_old_file(tmp_path, ragged):
    path = ragged.save(tmp_path / "r.npz")
    before = path.read_bytes()
    ragged.attrs["bad"] = object()  # not JSON: save fails validation before writing
    one_line_error(ragged.save, path, match="JSON")
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["r.npz"]


def test_load_errors(tmp_path, ragged):
    one_line_error(load, tmp_path / "missing.npz", match="no such file")
    (tmp_path / "x.txt").write_text("hi")
    msg = one_line_error(load, tmp_path / "x.txt")
    assert ".npz" in msg and ".zarr" in msg and ".csv" in msg
    msg = one_line_error(ragged.save, tmp_path / "x.h5")
    assert ".npz" in msg and ".zarr" in msg and ".csv" in msg
    # npz from another program
    np.savez(tmp_path / "foreign.npz", points=np.zeros((2, 3)))
    one_line_error(load, tmp_path / "foreign.npz", match="not written by rodwarp")
    # zarr from another program
    import zarr

    g = zarr.open_group(str(tmp_path / "foreign.zarr"), mode="w")
    g.create_array("points", data=np.zeros((2, 3)))
    one_line_error(load, tmp_path / "foreign.zarr", match="not written by rodwarp")
    # damaged npz and newer format
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    one_line_error(load, tmp_path / "junk.npz")
    meta = '{"format": "rodwarp.rodset", "format_version": %d, "units": "m"}' % (FORMAT_VERSION + 1)
    np.savez(tmp_path / "new.npz", meta=np.array(meta), points=np.zeros((2, 3)), offsets=[0, 2], radii=[1.0])
    one_line_error(load, tmp_path / "new.npz", match="upgrade")
    path = ragged.save(tmp_path / "r.npz")
    one_line_error(load, path, radius=1.0, diameter=2.0, match="not both")
    one_line_error(load, path, units="voxel", match="voxel_size")


def test_load_npz_converts_units(tmp_path, ragged):
    back = load(ragged.save(tmp_path / "r.npz"), units="m", diameter=5.0)
    assert back.units == "m"
    assert np.array_equal(back.radii, ragged.radii / 1000.0)  # stored radii win over diameter=


# -- CSV input ---------------------------------------------------------------------------------

def write(tmp_path, text, name="in.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_csv_grouping_extra_columns_and_diameter(tmp_path):
    p = write(tmp_path, "label,ROD, x ,y,z,note\n"
                        "a,7,0,0,0,hello\n" "a,7,1,0,0,\n\n" "b,3,0,1,0,x\n" "b,3,0,2,0,y\n" "b,3,0,3,0,z\n")
    one_line_error(load, p, match="or pass --diameter")
    rods = load(p, diameter=0.2, units="mm")
    assert rods.n_rods == 2 and rods.units == "mm"
    assert rods.vertex_counts.tolist() == [2, 3]
    assert np.array_equal(rods.radii, [0.1, 0.1])
    assert rods.attrs["source_rod_ids"] == [7, 3]
    assert np.array_equal(load(p, radius=0.3).radii, [0.3, 0.3])


@pytest.mark.parametrize("text, expect", [
    ("", "empty"),
    ("rod,x,y\n0,0,0\n0,1,0\n", "header lacks column(s) z"),
    ("id,x,y,z,radius\n0,0,0,0,1\n", "header lacks column(s) rod"),
    ("rod,x,y,z,radius\n", "rod set is empty"),
    ("rod,x,y,z,radius\n0,0,0,0,1\n0,nan,0,0,1\n", "line 3 column 'x'"),
    ("rod,x,y,z,radius\n0,0,0,0,1\n0,1,inf,0,1\n", "line 3 column 'y'"),
    ("rod,x,y,z,radius\n0,0,0,0,1\n0,1,abc,0,1\n", "'abc' is not a number"),
    ("rod,x,y,z,radius\n0,0,0,0,1\n0,1,0\n", "line 3"),
    ("rod,x,y,z,radius\n0,0,0,0,1\n0,1,0,0,1\n1,0,0,0,1\n1,1,0,0,1\n0,2,0,0,1\n", "line 6: rows of rod 0 are not contiguous"),
    ("rod,x,y,z,radius\n0,0,0,0,1\n1,0,0,0,1\n1,1,0,0,1\n", "line 2: rod 0 has only 1 vertex"),
    ("rod,x,y,z,radius\n0,0,0,0,1\n0,1,0,0,2\n", "line 3: radius 2.0 differs"),
    ("rod,x,y,z,radius\n0,0,0,0,-1\n0,1,0,0,-1\n", "radii must be positive"),
    ("rod,x,y,z,radius\n0.5,0,0,0,1\n0.5,1,0,0,1\n", "line 2: rod id 0.5 is not an integer"),
    ("rod,x,y,z,radius,x\n0,0,0,0,1,0\n", "column 'x' appears 2 times"),
])
def test_csv_errors(tmp_path, text, expect):
    msg = one_line_error(load, write(tmp_path, text))
    assert expect in msg, msg
    assert "in.csv" in msg


def test_csv_units_override_and_bad_units(tmp_path):
    p = write(tmp_path, "rod,x,y,z,radius\n0,0,0,0,1\n0,1,0,0,1\n")
    assert load(p, units="voxel").units == "voxel"
    msg = one_line_error(load, p, units="inch")
    assert "'m'" in msg and "'voxel'" in msg


# -- validation --------------------------------------------------------------------------------

def good(**over):
    kw = dict(points=np.zeros((5, 3)) + np.arange(5)[:, None], offsets=[0, 2, 5], radii=[0.1, 0.2])
    kw.update(over)
    return kw


@pytest.mark.parametrize("over, expect", [
    (dict(points=np.full((5, 3), np.nan)), "NaN"),
    (dict(radii=[0.1, np.inf]), "radii contains NaN or inf"),
    (dict(rest_points=np.full((5, 3), np.inf)), "rest_points contains"),
    (dict(velocities=np.full((5, 3), np.nan)), "velocities contains"),
    (dict(rest_points=np.zeros((4, 3))), "rest_points must have the same shape"),
    (dict(velocities=np.zeros((5, 2))), "velocities must have the same shape"),
    (dict(offsets=[1, 2, 5]), "start at 0"),
    (dict(offsets=[0, 2, 4]), "end at the vertex count 5"),
    (dict(offsets=[0, 1, 5]), "rod 0 has 1 vertices"),
    (dict(offsets=[0, 3, 2, 5]), "at least 2"),
    (dict(offsets=[0, 2.5, 5]), "whole numbers"),
    (dict(offsets=[[0, 2, 5]]), "1-D"),
    (dict(points=np.zeros((5, 2))), "(V, 3)"),
    (dict(points=np.zeros((0, 3)), offsets=[0], radii=[]), "rod set is empty"),
    (dict(radii=[0.1]), "radii must have shape (2,)"),
    (dict(radii=[0.1, 0.0]), "radius of rod 1"),
    (dict(radii=[-0.1, 0.1]), "radii must be positive"),
    (dict(units="inch"), "unknown units 'inch'; use one of 'm', 'mm', 'um', 'voxel'"),
    (dict(box=[[0, 0, 0], [1, 0, 1]]), "box lower corner"),
    (dict(box=[[0, 0, 0]]), "box must have shape (2, 3)"),
    (dict(contacts=Contacts([0], [2], [[0, 0, 0]], [0.0])), "contacts refer to rod 2"),
    (dict(contacts=Contacts([-1], [0], [[0, 0, 0]], [0.0])), "contacts refer to rod -1"),
    (dict(contacts="nope"), "Contacts object"),
    (dict(attrs={"f": lambda: 1}), "JSON"),
    (dict(points="abc"), "numeric"),
])
def test_validation_errors(over, expect):
    one_line_error(RodSet, **good(**over), match=expect)


def test_other_errors():
    one_line_error(Contacts, [0, 1], [1], [[0, 0, 0]], [0.0], match="contacts arrays disagree")
    one_line_error(Contacts, [0], [1], [[0, 0, np.nan]], [0.0], match="contacts.point")
    one_line_error(RodSet.from_polylines, [], 0.1, match="rod set is empty")
    one_line_error(RodSet.from_polylines, [np.zeros((1, 3))], 0.1, match="polyline 0 has 1 vertices")
    one_line_error(RodSet.from_polylines, [np.zeros((2, 3)), np.zeros((3, 2))], 0.1, match="polyline 1")
    one_line_error(RodSet.from_straight, np.zeros((1, 3)), np.zeros((1, 3)), 1.0, 0.1, match="direction of rod 0")
    one_line_error(RodSet.from_straight, np.zeros((1, 3)), [[1, 0, 0]], -1.0, 0.1, match="lengths must be positive")
    one_line_error(RodSet.from_straight, np.zeros((1, 3)), [[1, 0, 0]], 1.0, 0.1, n_vertices=1, match="n_vertices")
    rods = RodSet(**good())
    one_line_error(rods.rod, 2, match="out of range")
    one_line_error(rods.to_units, "voxel", match="voxel_size")
    one_line_error(rods.to_units, "mm", voxel_size=1e-3, match="only applies")
    one_line_error(rods.to_units, "voxel", voxel_size=-1.0, match="positive")
    one_line_error(rods.to_units, "ft", match="unknown units")
    rods.box = np.array([[1.0, 0, 0], [0, 1, 1]])  # assigned after construction: caught on save
    one_line_error(rods.validate, match="box lower corner")


# -- geometry ----------------------------------------------------------------------------------

def test_sizes_views_and_segments(ragged):
    assert (ragged.n_rods, ragged.n_vertices, ragged.n_segments) == (3, 15, 12)
    assert ragged.vertex_counts.tolist() == [2, 3, 10]
    assert ragged.rod_index.tolist() == [0] * 2 + [1] * 3 + [2] * 10
    assert np.array_equal(ragged.diameters, 2 * ragged.radii)
    r1 = ragged.rod(1)
    assert r1.shape == (3, 3) and np.shares_memory(r1, ragged.points)
    assert np.array_equal(ragged.rod(-1), ragged.points[5:])
    starts, ends, rod_of = ragged.segments()
    assert starts.shape == ends.shape == (ragged.n_vertices - ragged.n_rods, 3)
    assert rod_of.tolist() == [0] + [1] * 2 + [2] * 9
    # no segment joins the last vertex of a rod to the first of the next
    joins = {(tuple(ragged.points[o - 1]), tuple(ragged.points[o])) for o in ragged.offsets[1:-1]}
    assert not joins & {(tuple(s), tuple(e)) for s, e in zip(starts, ends)}
    seg = ragged.segment_lengths()
    assert np.allclose(seg, np.linalg.norm(ends - starts, axis=1))
    expect = [np.linalg.norm(np.diff(ragged.rod(i), axis=0), axis=1).sum() for i in range(3)]
    assert np.allclose(ragged.rod_lengths(), expect)


def test_from_straight_geometry():
    centers = np.array([[0.0, 0, 0], [1.0, 2.0, 3.0], [-0.3, 0.1, 0.7]])
    dirs = np.array([[2.0, 0, 0], [0, 0, -5.0], [1.0, 1.0, 1.0]])
    lengths = np.array([1.0, 0.25, 3.0])
    rods = RodSet.from_straight(centers, dirs, lengths, 0.01, n_vertices=7)
    assert rods.vertex_counts.tolist() == [7, 7, 7]
    assert np.allclose(rods.rod_lengths(), lengths, rtol=1e-14, atol=0)
    assert np.allclose(rods.segment_lengths(), np.repeat(lengths / 6, 6), rtol=1e-12)
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    for i in range(3):
        p = rods.rod(i)
        assert np.allclose(p[0] + p[-1], 2 * centers[i], atol=1e-15)  # symmetric about the centre
        assert np.allclose(p[-1] - p[0], lengths[i] * unit[i])
        assert np.allclose(p[::-1] + p, 2 * centers[i], atol=1e-15)
    assert np.array_equal(rods.radii, [0.01] * 3)


def test_bounding_box():
    rods = RodSet.from_polylines([[[0, 0, 0], [1, 0, 0]], [[0, 2, 0], [0, 2, 3]]], [0.1, 0.5])
    assert np.allclose(rods.bounding_box(), [[-0.5, -0.1, -0.5], [1.1, 2.5, 3.5]])


# -- units and derived sets --------------------------------------------------------------------

def test_units_exact(ragged):
    m = ragged.to_units("m")
    assert m.units == "m"
    for name in ("points", "radii", "rest_points", "velocities", "box"):
        assert np.array_equal(getattr(m, name), getattr(ragged, name) / 1000.0), name
    assert np.array_equal(m.contacts.point, ragged.contacts.point / 1000.0)
    assert np.array_equal(m.contacts.gap, ragged.contacts.gap / 1000.0)
    mm = m.to_units("mm")
    assert np.array_equal(mm.points, m.points * 1000.0)
    assert np.array_equal(mm.radii, m.radii * 1000.0)
    assert np.allclose(mm.points, ragged.points, rtol=1e-15)
    assert np.array_equal(ragged.to_units("um").points, ragged.points * 1000.0)
    same = ragged.to_units("mm")
    assert_same(ragged, same)
    assert not np.shares_memory(same.points, ragged.points)


def test_voxel_conversion(ragged):
    vs = 7.8e-5
    vox = ragged.to_units("m").to_units("voxel", voxel_size=vs)
    assert vox.units == "voxel"
    assert np.array_equal(vox.points, ragged.to_units("m").points / vs)
    back = vox.to_units("m", voxel_size=vs)
    assert np.array_equal(back.radii, vox.radii * vs)
    assert np.allclose(back.points, ragged.points / 1000.0, rtol=1e-14)
    assert np.allclose(vox.to_units("mm", voxel_size=vs).points, ragged.points, rtol=1e-14)
    one_line_error(vox.to_units, "m", match="voxel_size")


def test_copy_and_with_points(ragged):
    c = ragged.copy()
    assert_same(ragged, c)
    c.points[0, 0] += 1.0
    c.attrs["params"]["mu"] = 9.0
    assert ragged.points[0, 0] != c.points[0, 0] and ragged.attrs["params"]["mu"] == 0.3
    new = ragged.points + 1.0
    w = ragged.with_points(new)
    assert np.array_equal(w.points, new) and w.velocities is None and w.contacts is None
    assert w.radii is ragged.radii and w.offsets is ragged.offsets and w.rest_points is ragged.rest_points
    assert w.box is ragged.box and w.units == ragged.units and w.attrs == ragged.attrs
    v = np.ones_like(new)
    assert np.array_equal(ragged.with_points(new, velocities=v).velocities, v)
    one_line_error(ragged.with_points, new[:-1], match="offsets must end at the vertex count")


def test_contacts_normalised():
    c = Contacts([3, 1], [1, 2], [[0, 0, 0], [1, 1, 1]], [0.1, -0.2])
    assert c.rod_i.tolist() == [1, 1] and c.rod_j.tolist() == [3, 2]
    assert len(c) == 2 and c.rod_i.dtype == np.int64 and c.gap.dtype == np.float64
