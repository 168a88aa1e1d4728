"""The ParaView series of the main job: size and write time of the hand-written ASCII VTK that
rodwarp wrote before issue 15, of VTK's own XML writer (what rodwarp writes now: binary,
zlib, float32 points, polylines), and of meshio's VTU writer (binary, zlib; line segments,
meshio has no polyline cell), on frames of the main job's size (540 rods x 10 vertices,
103 frames)."""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import common

N_RODS, N_VERTICES, N_FRAMES = 540, 10, 103  # the main job: 1 + 2 x (5 s / 0.1 s + 1) frames


def legacy_write_vtp(path, positions, offsets, radii, t):
    """The ASCII writer rodwarp used before issue 15 (kept here only for the comparison)."""
    V = len(positions)
    rad = np.repeat(radii, np.diff(offsets))
    conn = " ".join(map(str, range(V)))
    offs = " ".join(map(str, offsets[1:]))
    pts = " ".join(f"{v:.9g}" for v in positions.ravel())
    text = f"""<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
 <PolyData>
  <FieldData><DataArray type="Float64" Name="TIME" NumberOfTuples="1" format="ascii">{t:.9g}</DataArray></FieldData>
  <Piece NumberOfPoints="{V}" NumberOfLines="{len(offsets) - 1}">
   <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">{pts}</DataArray></Points>
   <PointData Scalars="radius"><DataArray type="Float64" Name="radius" format="ascii">{" ".join(f"{r:.9g}" for r in rad)}</DataArray></PointData>
   <Lines>
    <DataArray type="Int64" Name="connectivity" format="ascii">{conn}</DataArray>
    <DataArray type="Int64" Name="offsets" format="ascii">{offs}</DataArray>
   </Lines>
  </Piece>
 </PolyData>
</VTKFile>
"""
    from rodwarp.rodset.files import write_text

    write_text(path, text)


def meshio_write_vtu(path, positions, offsets, radii, t):
    import meshio

    segs = np.concatenate([np.stack([np.arange(a, b - 1), np.arange(a + 1, b)], 1)
                           for a, b in zip(offsets[:-1], offsets[1:])])
    m = meshio.Mesh(positions, [("line", segs)], point_data={"radius": np.repeat(radii, np.diff(offsets))})
    m.write(str(path), file_format="vtu", compression="zlib")


def _frames(seed=0):
    from rodwarp.experiments import random_packing

    rods = random_packing(N_RODS, 1.0, 0.01, np.array([1.0, 1.0, 2.5]), n_vertices=N_VERTICES, seed=seed)
    rng = np.random.default_rng(seed)
    return rods, [rods.points + rng.normal(scale=1e-3, size=rods.points.shape) for _ in range(N_FRAMES)]


def run(quick: bool, device: str) -> dict:
    from rodwarp.rodset.trajectory import write_vtp

    rods, frames = _frames()
    writers = [("ascii (before issue 15)", legacy_write_vtp, "vtp", "hand-written"),
               ("vtk XML, zlib, float32 (now)", write_vtp, "vtp", "vtk")]
    try:
        import meshio  # noqa: F401

        writers.append(("meshio VTU, zlib", meshio_write_vtu, "vtu", "meshio"))
    except ImportError:
        common.log("meshio not installed: its VTU writer is not measured")
    rows = []
    repeats = common.n_repeats(quick)
    for label, fn, ext, lib in writers:
        series = []
        size = None
        for r in range(repeats):
            d = Path(tempfile.mkdtemp(prefix="rodwarp_vtk_"))
            t0 = time.perf_counter()
            for k, x in enumerate(frames):
                fn(d / f"frame_{k:05d}.{ext}", x, rods.offsets, rods.radii, 0.1 * k)
            series.append(time.perf_counter() - t0)
            size = sum(p.stat().st_size for p in d.iterdir())
            shutil.rmtree(d, ignore_errors=True)
        rows.append({"writer": label, "library": lib, "series_bytes": size, "frame_bytes": size / N_FRAMES,
                     "series_s": common.spread(series), "frame_ms": common.spread([1e3 * s / N_FRAMES for s in series])})
        common.log(f"{label}: {size / 1e6:.2f} MB, {np.median(series):.2f} s for {N_FRAMES} frames")
    try:
        import vtkmodules

        vtk_version = vtkmodules.__version__
    except (ImportError, AttributeError):
        vtk_version = None
    return {"title": "ParaView series of the main job: size and write time per writer",
            "frames": N_FRAMES, "rods": N_RODS, "vertices": N_RODS * N_VERTICES, "writers": rows,
            "vtk_version": vtk_version, "repeats": repeats}


def summary(rec: dict) -> list[dict]:
    base = rec["writers"][0]
    out = []
    for w in rec["writers"]:
        out.append({"benchmark": f"{w['writer']}: {rec['frames']} frames of {rec['vertices']} vertices",
                    "rodwarp": f"{w['series_bytes'] / 1e6:.2f} MB, {common.fmt_spread(w['series_s'], unit='s')}",
                    "peer": f"ascii {base['series_bytes'] / 1e6:.2f} MB, {common.fmt(base['series_s']['median'])} s",
                    "ratio": f"{base['series_bytes'] / w['series_bytes']:.3g}x smaller, "
                             f"{base['series_s']['median'] / w['series_s']['median']:.3g}x faster"})
    return out


def plot(rec: dict, outdir) -> list[dict]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ws = rec["writers"]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    names = [w["writer"].replace(" (", "\n(").replace(", ", ",\n", 1) for w in ws]
    ax[0].bar(names, [w["series_bytes"] / 1e6 for w in ws], color=["0.6", "tab:blue", "tab:orange"][:len(ws)])
    ax[0].set_ylabel("series size (MB)")
    ax[1].bar(names, [w["series_s"]["median"] for w in ws], color=["0.6", "tab:blue", "tab:orange"][:len(ws)])
    ax[1].set_ylabel(f"write time, {rec['frames']} frames (s)")
    for a in ax:
        a.tick_params(axis="x", labelsize=7)
    fig.tight_layout()
    fig.savefig(Path(outdir) / "vtk_writers.png", dpi=110)
    plt.close(fig)
    now = ws[1]
    return [{"file": "vtk_writers.png", "title": "ParaView series: size and write time per writer",
             "reading": f"VTK's writer makes the main job's series {ws[0]['series_bytes'] / now['series_bytes']:.2g}x "
                        f"smaller ({now['series_bytes'] / 1e6:.1f} MB) and writes it "
                        f"{ws[0]['series_s']['median'] / now['series_s']['median']:.2g}x faster than the ASCII writer."}]
