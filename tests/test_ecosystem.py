"""Outputs open in the field's tools (issue 15): trajectory.zarr and fields.zarr in xarray with
named dimensions and coordinates; the ParaView series read back by VTK."""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from typer.testing import CliRunner

from rodwarp.cli import app

xr = pytest.importorskip("xarray")

SHORT = ["simulate", "--rod-model", "elastic", "--vertices", "10", "--alpha", "20", "--n-rods", "12",
         "--entangle-duration", "0.02", "--duration", "0.02",
         "--save-every", "0.01", "--device", "cpu", "--quiet"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("eco") / "run"
    runner = CliRunner()
    res = runner.invoke(app, [*SHORT, "--out", str(out)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["analyze", str(out), "--quiet", "--no-figures"])
    assert res.exit_code == 0, res.output
    return out


def test_trajectory_opens_in_xarray_with_named_dims(run):
    import zarr

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # consolidated metadata: no fallback warning
        ds = xr.open_zarr(run / "trajectory.zarr")
    g = zarr.open_group(str(run / "trajectory.zarr"), mode="r")
    n = g.attrs["n_frames"]
    assert ds["positions"].dims == ("frame", "vertex", "xyz")
    assert set(ds.coords) >= {"time", "rod"}
    assert ds["time"].dims == ("frame",) and ds["rod"].dims == ("vertex",) and ds["radius"].dims == ("rod",)
    assert ds.sizes["vertex"] == 120 and ds.sizes["xyz"] == 3 and ds.sizes["frame"] >= n
    np.testing.assert_array_equal(ds["positions"].values[:n], g["positions"][:n])
    np.testing.assert_array_equal(ds["time"].values[:n], g["time"][:n])
    np.testing.assert_array_equal(ds["rod"].values, np.repeat(np.arange(12), 10))
    assert ds["positions"].attrs["units"] == "m" and ds.attrs["n_frames"] == n
    # selecting by label works: rod 3's vertices of the last frame
    last = ds["positions"].isel(frame=n - 1).where((ds["rod"] == 3).compute(), drop=True)
    assert last.shape == (10, 3) and np.isfinite(last.values).all()
    from rodwarp.rodset import load

    np.testing.assert_array_equal(ds["positions"].values[n - 1], load(run / "final.npz").points)


def test_fields_open_in_xarray_with_coordinates(run):
    from rodwarp.analysis import Fields

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ds = xr.open_zarr(run / "analysis" / "fields.zarr")
    f = Fields.load(run / "analysis" / "fields.zarr")
    for name in ("phi", "S", "c", "e", "n", "contacts"):
        assert ds[name].dims == ("z", "y", "x")
        np.testing.assert_array_equal(ds[name].values, getattr(f, name))
    for axis in "xyz":
        assert axis in ds.indexes  # index coordinates: label-based selection
        np.testing.assert_array_equal(ds[axis].values, getattr(f, axis))
    assert ds.attrs["radius"] == pytest.approx(f.radius) and ds.attrs["axis_order"] == "z,y,x"
    mid = ds["e"].sel(z=float(f.z[len(f.z) // 2]))
    assert mid.dims == ("y", "x")


def test_paraview_series_reads_back_in_vtk(run):
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    import zarr

    g = zarr.open_group(str(run / "trajectory.zarr"), mode="r")
    n = g.attrs["n_frames"]
    pvd = ET.parse(run / "trajectory.pvd").getroot()
    sets = pvd.findall("./Collection/DataSet")
    assert len(sets) == n
    offsets = np.asarray(g.attrs["offsets"])
    for k, ds in enumerate(sets):
        path = run / ds.get("file")
        head = path.read_bytes()[:400]
        assert b'format="appended"' in head and b"vtkZLibDataCompressor" in head  # binary, compressed
        r = vtkXMLPolyDataReader()
        r.SetFileName(str(path))
        r.Update()
        poly = r.GetOutput()
        assert poly.GetNumberOfPoints() == 120 and poly.GetNumberOfLines() == 12  # one polyline per rod
        pts = vtk_to_numpy(poly.GetPoints().GetData())
        np.testing.assert_allclose(pts, g["positions"][k], atol=1e-6)  # float32 copy of the float64 frame
        cells = poly.GetLines()
        np.testing.assert_array_equal(vtk_to_numpy(cells.GetOffsetsArray()), offsets)
        rad = vtk_to_numpy(poly.GetPointData().GetArray("radius"))
        np.testing.assert_allclose(rad, np.repeat(g["radius"][:], 10), rtol=1e-6)
        np.testing.assert_array_equal(vtk_to_numpy(poly.GetCellData().GetArray("rod")), np.arange(12))
        t = poly.GetFieldData().GetArray("TimeValue").GetValue(0)
        assert t == pytest.approx(float(ds.get("timestep")), rel=1e-8) == pytest.approx(g["time"][k], rel=1e-8)
