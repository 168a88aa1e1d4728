"""A rod set through time: trajectory (zarr), ParaView series (VTK polylines), checkpoints, snapshots.

Every writer is crash-safe: single files are written atomically (write, then rename), and
the trajectory records how many frames are complete only after a frame is written, so a
kill at any moment leaves every earlier frame, metric and checkpoint readable.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from rodwarp.rodset.files import atomic_path, consolidate_zarr, save_figure, write_text


class Trajectory:
    """Frames of vertex positions in ``trajectory.zarr`` (one chunk per frame).

    Arrays (named dimensions, so ``xarray.open_zarr`` gives a labelled dataset):
    ``positions`` (frame, vertex, xyz) float64 m, ``time`` (frame) s, ``rod`` (vertex) the rod
    of each vertex, ``radius`` (rod) m; ``time`` and ``rod`` are coordinates of ``positions``.
    Attributes: ``n_frames`` (frames complete; later frames are NaN), ``offsets`` and
    ``radii`` (the rod layout), ``units`` = "m".
    """

    def __init__(self, path, n_frames_max: int, offsets: np.ndarray, radii: np.ndarray, *, resume: bool = False):
        import zarr

        self.path = Path(path)
        V = int(offsets[-1])
        if resume and self.path.exists():
            self.group = zarr.open_group(str(self.path), mode="r+")
            if self.group["positions"].shape[0] < n_frames_max:
                self.group["positions"].resize((n_frames_max, V, 3))
                self.group["time"].resize((n_frames_max,))
        else:
            offsets = np.asarray(offsets)
            self.group = zarr.open_group(str(self.path), mode="w")
            pos = self.group.create_array("positions", shape=(n_frames_max, V, 3), chunks=(1, V, 3), dtype="f8",
                                          fill_value=np.nan, dimension_names=("frame", "vertex", "xyz"))
            pos.attrs.update({"units": "m", "coordinates": "time rod", "long_name": "vertex position"})
            # one chunk per frame, like positions: a frame's time is written without reading the rest
            t = self.group.create_array("time", shape=(n_frames_max,), chunks=(1,), dtype="f8",
                                        fill_value=np.nan, dimension_names=("frame",))
            t.attrs.update({"units": "s", "long_name": "simulated time"})
            rod = self.group.create_array("rod", data=np.repeat(np.arange(len(offsets) - 1, dtype=np.int32),
                                                                np.diff(offsets)), dimension_names=("vertex",))
            rod.attrs["long_name"] = "rod of each vertex"
            rad = self.group.create_array("radius", data=np.asarray(radii, dtype=np.float64),
                                          dimension_names=("rod",))
            rad.attrs.update({"units": "m", "long_name": "rod radius"})
            self.group.attrs.update({"n_frames": 0, "offsets": offsets.tolist(),
                                     "radii": np.asarray(radii).tolist(), "units": "m",
                                     "axes": "frame, vertex, xyz"})

    @property
    def n_frames(self) -> int:
        return int(self.group.attrs["n_frames"])

    def write(self, index: int, t: float, positions: np.ndarray) -> None:
        """Write frame ``index`` and only then count it as complete."""
        try:
            self.group["positions"][index] = positions
            self.group["time"][index] = t
            self.group.attrs["n_frames"] = index + 1
        except OSError as e:
            raise OSError(e.errno, e.strerror or str(e), str(self.path)) from None

    def finish(self) -> None:
        """Consolidate the metadata once the last frame is written."""
        consolidate_zarr(self.path)


def _quiet_vtk() -> None:
    """VTK reports a failed write on stderr itself (many lines); rodwarp raises an OSError that
    the CLI prints as one line instead."""
    from vtkmodules.vtkCommonCore import vtkLogger, vtkObject

    vtkObject.GlobalWarningDisplayOff()
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_OFF)


def write_vtp(path, positions: np.ndarray, offsets: np.ndarray, radii: np.ndarray, t: float) -> None:
    """One frame as VTK XML PolyData, written by VTK itself, atomically.

    A polyline per rod, ``radius`` per point (ParaView: Tube filter, vary radius by scalar),
    ``rod`` per cell, the time as field data ``TimeValue``. Binary (appended, raw) and
    zlib-compressed; points in float32 (sub-micrometre at metre scale: a view of the run, the
    exact float64 positions are in ``trajectory.zarr``).

    Parameters
    ----------
    path : path-like
        ``.vtp`` file to write.
    positions : (V, 3) float
        Vertex positions (m).
    offsets : (N+1,) int
        Rod layout: rod k is vertices ``offsets[k]:offsets[k+1]``.
    radii : (N,) float
        Rod radii (m).
    t : float
        Time of the frame (s).
    """
    _quiet_vtk()
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkDoubleArray, vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    offsets = np.asarray(offsets, dtype=np.int64)
    V = int(offsets[-1])
    pts = vtkPoints()
    pts.SetData(numpy_to_vtk(np.ascontiguousarray(positions, dtype=np.float32), deep=True))
    lines = vtkCellArray()
    lines.SetData(numpy_to_vtkIdTypeArray(offsets.copy(), deep=True),
                  numpy_to_vtkIdTypeArray(np.arange(V, dtype=np.int64), deep=True))
    poly = vtkPolyData()
    poly.SetPoints(pts)
    poly.SetLines(lines)
    rad = numpy_to_vtk(np.repeat(np.asarray(radii, dtype=np.float32), np.diff(offsets)), deep=True)
    rad.SetName("radius")
    poly.GetPointData().AddArray(rad)
    poly.GetPointData().SetActiveScalars("radius")
    rod = numpy_to_vtk(np.arange(len(offsets) - 1, dtype=np.int32), deep=True)
    rod.SetName("rod")
    poly.GetCellData().AddArray(rod)
    tv = vtkDoubleArray()
    tv.SetName("TimeValue")
    tv.InsertNextValue(float(t))
    poly.GetFieldData().AddArray(tv)
    with atomic_path(path) as tmp:
        w = vtkXMLPolyDataWriter()
        w.SetFileName(str(tmp))
        w.SetInputData(poly)
        w.SetDataModeToAppended()
        w.EncodeAppendedDataOff()  # raw bytes, not base64
        w.SetCompressorTypeToZLib()
        w.SetHeaderTypeToUInt64()
        if w.Write() != 1:
            import errno

            from vtkmodules.vtkCommonMisc import vtkErrorCode

            code = w.GetErrorCode()
            why = vtkErrorCode.GetStringFromErrorCode(code) or "unknown error"
            if code == vtkErrorCode.OutOfDiskSpaceError or "No space" in why:
                raise OSError(errno.ENOSPC, "No space left on device", str(path))
            raise OSError(errno.EIO, f"VTK could not write the frame ({why})", str(path))


def write_pvd(path, entries) -> None:
    """ParaView collection of (time, file) pairs: open this file to play the run."""
    rows = "\n".join(f'  <DataSet timestep="{t:.9g}" part="0" file="{f}"/>' for t, f in entries)
    write_text(path, f'<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n <Collection>\n{rows}\n'
                     f' </Collection>\n</VTKFile>\n')


def write_checkpoint_file(path, arrays: dict, meta: dict) -> Path:
    """Write one checkpoint file ``path`` (npz: the arrays plus JSON ``meta``) atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, meta=np.array(json.dumps(meta)), **arrays)
    return path


def read_checkpoint_file(path):
    """``(arrays, meta)`` of the checkpoint file ``path`` (written by :func:`write_checkpoint_file`)."""
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        arrays = {k: z[k] for k in z.files if k != "meta"}
    return arrays, meta


def save_checkpoint(directory, step: int, arrays: dict, meta: dict, keep: int = 2) -> Path:
    """Write ``ckpt_<step>.npz`` atomically (arrays plus JSON ``meta``); keep the newest ``keep``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = write_checkpoint_file(directory / f"ckpt_{step:010d}.npz", arrays, meta)
    for old in sorted(directory.glob("ckpt_*.npz"))[:-keep]:
        old.unlink(missing_ok=True)
    return path


def latest_checkpoint(directory):
    """(arrays, meta) of the newest readable checkpoint in ``directory``, or None."""
    for path in sorted(Path(directory).glob("ckpt_*.npz"), reverse=True):
        try:
            return read_checkpoint_file(path)
        except Exception:
            continue  # a torn file cannot exist (atomic writes), but skip anything unreadable
    return None


def plot_snapshots(path, frames, offsets, box=None) -> None:
    """Side views (x-z) of the packing at the given (title, positions) frames, as one PNG.

    Parameters
    ----------
    path : path-like
        PNG to write (atomically).
    frames : sequence of (str, ndarray (V, 3))
        Title and vertex positions (m) of each view.
    offsets : (N+1,) int
        Rod layout.
    box : (2, 3) array-like, optional
        Container corners (m), drawn dashed.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    # its own Figure (no pyplot): the process's matplotlib backend is left alone
    fig = Figure(figsize=(3.2 * len(frames), 5.5))
    axes = np.atleast_1d(fig.subplots(1, len(frames), sharey=True))
    for ax, (title, x) in zip(axes, frames):
        segs = [x[offsets[r]:offsets[r + 1]][:, [0, 2]] for r in range(len(offsets) - 1)]
        ax.add_collection(LineCollection(segs, linewidths=0.6, colors="0.2"))
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.autoscale()
        if box is not None:
            ax.add_patch(Rectangle((box[0][0], box[0][2]), box[1][0] - box[0][0], box[1][2] - box[0][2],
                                   fill=False, ls="--", lw=0.6, color="tab:blue"))
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("z (m)")
    # fixed margins: tight_layout measured every label's extent and took 0.4 s of the main job
    w = 3.2 * len(frames)
    fig.subplots_adjust(left=0.75 / w, right=1.0 - 0.15 / w, bottom=0.09, top=0.95, wspace=0.08)
    save_figure(fig, path)
