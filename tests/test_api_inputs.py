"""Bad input at the public Python API's boundary, and two bad inputs through the command line.

Every numeric argument of the public constructors and functions below is fed NaN, +-inf, 0, a
negative, a tiny (1e-300) and a huge (1e300) value.  Each row of :data:`NUMBERS` states the
documented range of its argument: a value inside it must be accepted, a value outside it
refused with a ``ValueError`` (:class:`RodwarpError`) whose one-line message names the
argument.  A wrong kind of argument (a string, a dict, a list where a RodSet goes) must raise a
``TypeError`` that names the argument and is also a :class:`RodwarpError`, so the command line
prints it as one line.  Nothing here steps a simulation: the whole file runs in seconds.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from rodwarp import RodSet, RodwarpError
from rodwarp.analysis import (Fields, average_crossing_number, compute_fields, field_statistics, find_tangles,
                              gauss_linking, histogram, resolve_params)
from rodwarp.rodset import detect_contacts
from rodwarp.sim import ContactLaw, Material, Model, ModelBuilder, RodSolver, run
from rodwarp.sim.walls import Cylinder

NAN, INF = math.nan, math.inf
#: the values every numeric argument is fed
VALUES = {"nan": NAN, "+inf": INF, "-inf": -INF, "zero": 0.0, "negative": -1.0, "tiny": 1e-300, "huge": 1e300}


def within(lo=-INF, hi=INF, *, lo_open=False, hi_open=False, whole=False):
    """The predicate of a documented range [lo, hi] (open ends on request; NaN and infinities
    are never inside, and ``whole`` asks for a whole number)."""
    def inside(v):
        if not math.isfinite(v) or (whole and v != round(v)):
            return False
        return (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    return inside


# ----------------------------------------------------------------------------------------------
# small inputs
# ----------------------------------------------------------------------------------------------

def rods(radius=0.001, z=0.0, units="m", velocity=None):
    """Two parallel 0.1 m rods 1 cm apart; ``z`` is the height of rod 0's second vertex."""
    pts = [[[0, 0, 0], [0.1, 0, z]], [[0, 0.01, 0], [0.1, 0.01, 0]]]
    kw = {} if velocity is None else {"velocities": np.array([[0, 0, velocity], [0, 0, 0], [0, 0, 0], [0, 0, 0]])}
    return RodSet.from_polylines(pts, radius, units=units, **kw)


ROD = rods()


@pytest.fixture(scope="module")
def model():
    return ModelBuilder(ROD, gravity=(0, 0, -9.81), rod_model="rigid").finalize()


def builder(**options):
    return ModelBuilder(ROD, **options)


def fields(**kw):
    e = np.ones((3, 3, 3))
    base = dict(x=np.arange(3.0), y=np.arange(3.0), z=np.arange(3.0), radius=1.0, spacing=1.0)
    return Fields(e=e, n=e, **{**base, **kw})


def fields_params(**kw):
    # keep_outside: the ball may exceed the rods' bounding box, so only the argument's own range counts
    return resolve_params(ROD, keep_outside=True, **kw)


# ----------------------------------------------------------------------------------------------
# numeric arguments: (label, the call with value v, the documented range, the name the message holds)
# ----------------------------------------------------------------------------------------------

NUMBERS = [
    # the engine (SI units)
    ("Material young", lambda v: Material(young=v), within(1.0, 1e13), "young"),
    ("Material density", lambda v: Material(density=v), within(1e-2, 1e5), "density"),
    ("Material poisson", lambda v: Material(poisson=v), within(-1.0, 0.5, lo_open=True, hi_open=True), "poisson"),
    ("ModelBuilder gravity z", lambda v: builder(gravity=(0, 0, v)), within(-1e5, 1e5), "gravity"),
    ("ModelBuilder mu", lambda v: builder(mu=v), within(0.0, 10.0), "mu"),
    ("ModelBuilder damping", lambda v: builder(damping=v), within(0.0, 1e6), "damping"),
    ("ModelBuilder contact_distance", lambda v: builder(contact_distance=v), within(0.0, 1e6), "contact_distance"),
    ("ModelBuilder pinned", lambda v: builder(pinned=[v]).finalize(), within(0, ROD.n_vertices - 1, whole=True),
     "pinned"),
    ("ModelBuilder rods radius", lambda v: ModelBuilder(rods(radius=v)), within(1e-9, 1e6), "radi"),
    ("ModelBuilder rods coordinate", lambda v: ModelBuilder(rods(z=v)), within(-1e6, 1e6), "points"),
    ("Model mu", lambda v: Model(ROD, mu=v), within(0.0, 10.0), "mu"),
    ("add_plane offset", lambda v: builder().add_plane((0, 0, 1), v), within(-1e6, 1e6), "offset"),
    ("add_plane normal z", lambda v: builder().add_plane((0, 0, v), 0.0),
     lambda v: math.isfinite(v) and v != 0, "normal"),
    ("add_plane mu", lambda v: builder().add_plane((0, 0, 1), 0.0, mu=v), within(0.0, 10.0), "mu"),
    ("add_box lower z", lambda v: builder().add_box((-1, -1, v), (1, 1, 1)), within(-1e6, 1.0, hi_open=True),
     "lower"),
    ("add_box mu", lambda v: builder().add_box((-1, -1, -1), (1, 1, 1), mu=v), within(0.0, 10.0), "mu"),
    ("Cylinder radius", lambda v: Cylinder.make((0, 0, 0), (0, 0, 1), v), within(0.0, 1e6, lo_open=True), "radius"),
    ("Cylinder point x", lambda v: Cylinder.make((v, 0, 0), (0, 0, 1), 1.0), within(-1e6, 1e6), "point"),
    ("ContactLaw delta", lambda v: ContactLaw("imc", delta=v), within(0.0, 1e6, lo_open=True), "delta"),
    ("ContactLaw nu", lambda v: ContactLaw("imc", nu=v), within(0.0, 1e3, lo_open=True), "nu"),
    ("ContactLaw stiffness", lambda v: ContactLaw("imc", stiffness=v), within(0.0, 1e15, lo_open=True), "stiffness"),
    ("set_drive amplitude", lambda v, m: m.control().set_drive(v, 10.0), within(-1e6, 1e6), "amplitude"),
    ("set_drive frequency", lambda v, m: m.control().set_drive(0.01, v), within(0.0, 1e6), "frequency"),
    ("set_ramp speed", lambda v, m: m.control().set_ramp(v, 1.0), within(-1e3, 1e3), "speed"),
    ("set_ramp duration", lambda v, m: m.control().set_ramp(0.1, v),
     lambda v: v == INF or within(0.0, lo_open=True)(v), "duration"),
    ("RodSolver relax", lambda v, m: RodSolver(m, relax=v), within(0.0, 2.0, lo_open=True, hi_open=True), "relax"),
    ("RodSolver iterations", lambda v, m: RodSolver(m, iterations=v), within(1, 100_000, whole=True), "iterations"),
    ("RodSolver tolerance", lambda v, m: RodSolver(m, tolerance=v), within(0.0, 1e3), "tolerance"),
    ("RodSolver skin", lambda v, m: RodSolver(m, skin=v), within(0.0, 1e6, lo_open=True), "skin"),
    ("run dt", lambda v, m: run(RodSolver(m), m.state(), 0.0, v), within(0.0, lo_open=True), "dt"),
    # at dt = 1 s, at most 1e9 steps (1e-300 s is zero steps)
    ("run duration", lambda v, m: run(RodSolver(m), m.state(), v, 1.0), within(0.0, 1e9), "duration"),
    # rod sets (any unit): finite, within MAX_COORDINATE = 1e12 of the set's unit
    ("from_polylines coordinate", lambda v: rods(z=v), within(-1e12, 1e12), "points"),
    ("from_polylines radii", lambda v: rods(radius=v), within(0.0, 1e12, lo_open=True), "radi"),
    ("RodSet velocities", lambda v: rods(velocity=v), within(-1e12, 1e12), "velocities"),
    ("detect_contacts tolerance", lambda v: detect_contacts(ROD, v), within(-1e12, 1e12), "tolerance"),
    # the analysis (lengths in the rods' units: d = 2 mm, l = 0.1 m, R = sqrt(d l) = 14 mm)
    ("resolve_params radius", lambda v: fields_params(radius=v), within(0.001, 1e12), "radius"),
    ("resolve_params spacing", lambda v: fields_params(spacing=v),
     within(0.01 * math.sqrt(2e-4), 2 * math.sqrt(2e-4)), "spacing"),
    ("resolve_params contact_tolerance", lambda v: fields_params(contact_tolerance=v), within(0.0, 1e12),
     "contact_tolerance"),
    ("resolve_params diameter", lambda v: fields_params(diameter=v), within(1e-10, 1e12), "diameter"),
    ("compute_fields radius", lambda v: compute_fields(ROD, radius=v, keep_outside=True),
     within(0.001, 1e12), "radius"),
    ("Fields radius", lambda v: fields(radius=v), within(0.0, 1e12, lo_open=True), "radius"),
    ("Fields spacing", lambda v: fields(spacing=v), within(0.0, 1e12, lo_open=True), "spacing"),
    ("field_statistics bins", lambda v: field_statistics(fields(), bins=v, power_laws=False),
     within(1, 100_000, whole=True), "bins"),
    ("field_statistics contact_cluster_fraction",
     lambda v: field_statistics(fields(), contact_cluster_fraction=v, power_laws=False), within(0.0, 1.0),
     "contact_cluster_fraction"),
    ("histogram bins", lambda v: histogram([1.0, 2.0], bins=v), within(1, 100_000, whole=True), "bins"),
    ("histogram range", lambda v: histogram([1.0, 2.0], range=(v, 3.0)), within(hi=3.0, hi_open=True), "range"),
    ("find_tangles e_lb", lambda v: find_tangles(np.ones((2, 2, 2)), np.ones((2, 2, 2), bool), v),
     within(), "e_lb"),
    ("average_crossing_number coordinate", lambda v: average_crossing_number([[0, 0, 0], [1, 0, v]],
                                                                             [[0, 1, 1], [0, -1, 1]]),
     within(-1e12, 1e12), "a holds"),
    ("gauss_linking coordinate", lambda v: gauss_linking([0, 0, 0], [1, 0, 0], [0, 1, 1], [0, -1, v]),
     within(-1e12, 1e12), "p4"),
]


@pytest.mark.parametrize("value", list(VALUES.values()), ids=list(VALUES))
@pytest.mark.parametrize("label, call, inside, name", NUMBERS, ids=[row[0] for row in NUMBERS])
def test_numeric_argument(label, call, inside, name, value, request):
    takes_model = call.__code__.co_argcount == 2
    go = (lambda: call(value, request.getfixturevalue("model"))) if takes_model else (lambda: call(value))
    if inside(value):
        go()  # within the documented range: accepted
        return
    with pytest.raises(RodwarpError) as info:
        go()
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert name in msg, f"{label} = {value!r}: the message does not name {name!r}: {msg}"


def test_the_engine_takes_physical_rods_only():
    # RodSet takes any unit up to 1e12 of it; the engine's rods are metres within 1000 km, 1 nm thick or more
    with pytest.raises(RodwarpError, match=r"rods\.points must be <= 1e\+06 m, got 1e\+09"):
        ModelBuilder(rods(z=1e9))
    with pytest.raises(RodwarpError, match=r"rods\.radii must be >= 1e-09 m"):
        ModelBuilder(rods(radius=1e-12))
    with pytest.raises(RodwarpError, match="rods.radii"):
        ModelBuilder(rods(radius=1e-7, units="mm"))  # 1e-10 m, in metres as the engine converts it
    ModelBuilder(rods(radius=1e-3, units="mm"))


# ----------------------------------------------------------------------------------------------
# the wrong kind of argument
# ----------------------------------------------------------------------------------------------

WRONG_KINDS = [
    ("compute_fields('str')", lambda: compute_fields("str"), "rods"),
    ("compute_fields device=3", lambda: compute_fields(ROD, device=3, keep_outside=True), "device"),
    ("compute_fields contacts=[]", lambda: compute_fields(ROD, contacts=[], keep_outside=True), "contacts"),
    ("field_statistics({'e': 1})", lambda: field_statistics({"e": 1}), "fields"),
    ("ModelBuilder([[0, 0, 0]])", lambda: ModelBuilder([[0, 0, 0]], gravity=(0, 0, -9.81)), "rods"),
    ("ModelBuilder material='steel'", lambda: ModelBuilder(ROD, "steel"), "material"),
    ("ModelBuilder gravity=9.81", lambda: builder(gravity=9.81), "gravity"),
    ("ModelBuilder mu='0.2'", lambda: builder(mu="0.2"), "mu"),
    ("ModelBuilder mu=True", lambda: builder(mu=True), "mu"),
    ("ModelBuilder gravit=...", lambda: builder(gravit=(0, 0, -9.81)), "gravit"),
    ("ModelBuilder pinned='0'", lambda: builder(pinned="0"), "pinned"),
    ("add_box lower='low'", lambda: builder().add_box("low", (1, 1, 1)), "lower"),
    ("add_wall 'floor'", lambda: builder().add_wall("floor"), "wall"),
    ("Material young='2e11'", lambda: Material(young="2e11"), "young"),
    ("RodSet.from_polylines('abc')", lambda: RodSet.from_polylines("abc", 0.1), "polylines"),
    ("RodSet.from_polylines radii='thick'", lambda: RodSet.from_polylines([[[0, 0, 0], [1, 0, 0]]], "thick"),
     "radii"),
    ("RodSet points={}", lambda: RodSet({}, [0, 2], [0.1]), "points"),
    ("detect_contacts('rods')", lambda: detect_contacts("rods"), "rods"),
    ("histogram bins='10'", lambda: histogram([1.0], bins="10"), "bins"),
    ("average_crossing_number('a')", lambda: average_crossing_number("a", [[0, 0, 0], [1, 0, 0]]), "a"),
    ("Fields radius='1'", lambda: fields(radius="1"), "radius"),
]


@pytest.mark.parametrize("label, call, name", WRONG_KINDS, ids=[row[0] for row in WRONG_KINDS])
def test_wrong_kind_is_a_type_error_naming_the_argument(label, call, name):
    with pytest.raises(TypeError) as info:
        call()
    assert isinstance(info.value, RodwarpError), f"{label}: the CLI would not print it as one line"
    msg = str(info.value)
    assert "\n" not in msg and name in msg, msg


# ----------------------------------------------------------------------------------------------
# through the command line: exit 2, one error line, no NumPy warning
# ----------------------------------------------------------------------------------------------

def _csv(path, rows):
    path.write_text("rod,x,y,z,radius\n" + "".join(f"{r},{x},{y},{z},{rad}\n" for r, x, y, z, rad in rows))
    return path


def _cli(args, cwd, **env):
    """``rodwarp ARGS`` in a fresh interpreter: (exit code, stderr lines that are not blank)."""
    res = subprocess.run([sys.executable, "-m", "rodwarp.cli", *map(str, args)], cwd=cwd, capture_output=True,
                         text=True, env={**os.environ, **env}, timeout=300)
    return res.returncode, [ln for ln in res.stderr.splitlines() if ln.strip()]


def _one_error(rc, lines, *fragments):
    assert rc == 2, lines
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    assert "Warning" not in lines[0]
    for f in fragments:
        assert f in lines[0], lines[0]


@pytest.mark.parametrize("command", ["analyze", "simulate"])
def test_huge_coordinates_are_one_clear_error(tmp_path, command):
    src = _csv(tmp_path / "big.csv", [(0, 0, 0, 0, 0.01), (0, 1e300, 0, 0, 0.01), (1, 0, 1e300, 0, 0.01),
                                      (1, 0, 1e300, 1e300, 0.01)])
    args = ["analyze", src] if command == "analyze" else ["simulate", "--initial", src]
    rc, lines = _cli([*args, "--out", tmp_path / "out"], tmp_path)
    # the real cause (not "rods 0 and 1 are duplicates" after NumPy's overflow warnings)
    _one_error(rc, lines, "points hold 1e+300 m", "too large to be a length in 'm'")
    assert not (tmp_path / "out").exists()


@pytest.fixture()
def small_csv(tmp_path):
    return _csv(tmp_path / "ok.csv", [(0, 0, 0, 0, 0.001), (0, 0.1, 0, 0, 0.001), (1, 0, 0.01, 0, 0.001),
                                      (1, 0.1, 0.01, 0, 0.001)])


def test_kernel_cache_that_is_a_file(tmp_path, small_csv):
    cache = tmp_path / "cache"
    cache.write_text("not a folder")
    rc, lines = _cli(["analyze", small_csv, "--keep-outside", "--out", tmp_path / "out"], tmp_path,
                     RODWARP_KERNEL_CACHE=str(cache))
    _one_error(rc, lines, f"RODWARP_KERNEL_CACHE={cache}", "is a file, not a folder",
               "unset RODWARP_KERNEL_CACHE or point it at a writable folder")
    assert "--out" not in lines[0]


def test_kernel_cache_in_a_read_only_place(tmp_path, small_csv, monkeypatch, capsys):
    """A read-only mount, simulated: root ignores permission bits, so a chmod cannot make one."""
    import errno

    from rodwarp import _warp, validation
    from rodwarp.cli import main

    cache = tmp_path / "ro" / "cache"
    probe = validation.probe_write

    def read_only(directory):
        if os.path.abspath(directory).startswith(str(cache)):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(directory))
        probe(directory)  # --out is writable

    monkeypatch.setattr(validation, "probe_write", read_only)
    monkeypatch.setattr(_warp, "_configured", False)  # check the cache again in this process
    monkeypatch.setenv("RODWARP_KERNEL_CACHE", str(cache))
    capsys.readouterr()
    rc = main(["analyze", str(small_csv), "--keep-outside", "--out", str(tmp_path / "out")])
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    _one_error(rc, lines, "RODWARP_KERNEL_CACHE=", "is not a writable folder (Read-only file system)",
               "unset RODWARP_KERNEL_CACHE or point it at a writable folder")
