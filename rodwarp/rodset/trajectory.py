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
    Attributes: ``n_frames`` (frames complete; while a run goes on later frames are NaN, and
    :meth:`finish` trims the arrays to these frames), ``offsets`` and
    ``radii`` (the rod layout), ``units`` = "m".
    """

    def __init__(self, path, n_frames_max: int, offsets: np.ndarray, radii: np.ndarray, *, resume: bool = False):
        import zarr

        self.path = Path(path)
        V = int(offsets[-1])
        if resume and self.path.exists():
            # not the consolidated metadata: it records the shapes a finished run trimmed to,
            # and the arrays grow back here
            self.group = zarr.open_group(str(self.path), mode="r+", use_consolidated=False)
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
        """Trim the arrays to the frames written, then consolidate the metadata.

        The arrays are allocated for the most frames a run can take (a stage's first sample
        may coincide with the previous stage's last), so the unused tail would stay NaN and
        ``positions[-1]`` would not be the last frame; after this the arrays hold exactly
        ``n_frames`` frames.  A resumed run grows them again (see ``__init__``).
        """
        n = self.n_frames
        V = self.group["positions"].shape[1]
        try:
            self.group["positions"].resize((n, V, 3))
            self.group["time"].resize((n,))
        except OSError as e:
            raise OSError(e.errno, e.strerror or str(e), str(self.path)) from None
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


def snapshot_view(frames, offsets, box=None, q: float = 99.0, margin: float = 0.05) -> dict:
    """View limits of the side views (x-z) that a few far rods do not stretch.

    A single rod thrown high by the shaking once set the shared z range, squashing every
    packing into the bottom fifth of ``snapshots.png``.  The limits here span the container
    and the rods between the ``100 - q`` and ``q`` percentiles of the rods' extents (lowest and
    highest vertex of each rod), plus ``margin`` of the span; rods reaching beyond are
    counted, so the figure can say where they went.

    Parameters
    ----------
    frames : sequence of (str, ndarray (V, 3))
        Title and vertex positions (m) of each view.
    offsets : (N+1,) int
        Rod layout.
    box : (2, 3) array-like, optional
        Container corners (m): always inside the view.
    q : float
        Percentile (0-100) of the rods' extents the view reaches.
    margin : float
        Fraction of the span added on each side.

    Returns
    -------
    dict
        ``z``: (lo, hi) shared by every view; ``x``: one (lo, hi) per frame; ``above``,
        ``below``, ``beside``: per frame, the rods reaching above, below, or left or right of
        the view; ``above_x``: per frame, the mean x of the rods above (None when none).
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    starts = offsets[:-1]
    box = None if box is None else np.asarray(box, dtype=float)

    def extent(x, axis):
        v = x[:, axis]
        return np.minimum.reduceat(v, starts), np.maximum.reduceat(v, starts)

    def bounds(lows, highs, box_lo=None, box_hi=None):
        lo = float(np.percentile(lows, 100.0 - q)) if lows.size else 0.0
        hi = float(np.percentile(highs, q)) if highs.size else 1.0
        if box_lo is not None:
            lo, hi = min(lo, box_lo), max(hi, box_hi)
        pad = margin * max(hi - lo, 1e-12)
        return lo - pad, hi + pad

    zs = [extent(np.asarray(x), 2) for _, x in frames]
    zlo, zhi = bounds(np.concatenate([a for a, _ in zs]), np.concatenate([b for _, b in zs]),
                      None if box is None else box[0][2], None if box is None else box[1][2])
    out = {"z": (zlo, zhi), "x": [], "above": [], "below": [], "beside": [], "above_x": []}
    for (_, x), (zmin, zmax) in zip(frames, zs):
        x = np.asarray(x)
        xmin, xmax = extent(x, 0)
        xlo, xhi = bounds(xmin, xmax, None if box is None else box[0][0], None if box is None else box[1][0])
        up = zmax > zhi
        out["x"].append((xlo, xhi))
        out["above"].append(int(np.count_nonzero(up)))
        out["below"].append(int(np.count_nonzero(zmin < zlo)))
        out["beside"].append(int(np.count_nonzero((xmin < xlo) | (xmax > xhi))))
        centre_x = np.add.reduceat(x[:, 0], starts) / np.diff(offsets)
        out["above_x"].append(float(np.mean(centre_x[up])) if up.any() else None)
    return out


def snapshots_figure(frames, offsets, box=None):
    """The figure of :func:`plot_snapshots` (same arguments but the path), not yet written."""
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    view = snapshot_view(frames, offsets, box)
    # its own Figure (no pyplot): the process's matplotlib backend is left alone
    fig = Figure(figsize=(3.2 * len(frames), 5.5))
    axes = np.atleast_1d(fig.subplots(1, len(frames), sharey=True))
    for k, (ax, (title, x)) in enumerate(zip(axes, frames)):
        segs = [x[offsets[r]:offsets[r + 1]][:, [0, 2]] for r in range(len(offsets) - 1)]
        # autolim=False: the far rods must not enter the data limits; the robust box does
        ax.add_collection(LineCollection(segs, linewidths=0.6, colors="0.2"), autolim=False)
        ax.set_title(title, fontsize=9)
        (xlo, xhi), (zlo, zhi) = view["x"][k], view["z"]
        ax.update_datalim([(xlo, zlo), (xhi, zhi)])
        ax.autoscale_view(tight=True)
        ax.set_ylim(zlo, zhi)
        # adjustable="datalim": equal scales by widening the (autoscaled) x range, never by
        # shrinking the z range set here
        ax.set_aspect("equal", adjustable="datalim")
        if box is not None:
            ax.add_patch(Rectangle((box[0][0], box[0][2]), box[1][0] - box[0][0], box[1][2] - box[0][2],
                                   fill=False, ls="--", lw=0.6, color="tab:blue"))
        n_up = view["above"][k]
        if n_up:
            xa = float(np.clip(view["above_x"][k], *view["x"][k]))
            ax.annotate(f"{n_up} rod{'s' if n_up > 1 else ''} above the view", xy=(xa, 1.0),
                        xycoords=("data", "axes fraction"), xytext=(0.5, 0.9), textcoords="axes fraction",
                        ha="center", va="top", fontsize=7, color="tab:red",
                        bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="none", alpha=0.8),
                        arrowprops=dict(arrowstyle="->", color="tab:red", lw=0.8))
        others = view["below"][k] + view["beside"][k]
        if others:
            ax.text(0.02, 0.01, f"{others} rod{'s' if others > 1 else ''} partly beside or below the view",
                    transform=ax.transAxes, fontsize=6, color="tab:red", va="bottom")
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("z (m)")
    # fixed margins: tight_layout measured every label's extent and took 0.4 s of the main job
    w = 3.2 * len(frames)
    fig.subplots_adjust(left=0.75 / w, right=1.0 - 0.15 / w, bottom=0.09, top=0.95, wspace=0.08)
    return fig


def plot_snapshots(path, frames, offsets, box=None) -> None:
    """Side views (x-z) of the packing at the given (title, positions) frames, as one PNG.

    The views span the container and nearly all rods (:func:`snapshot_view`); rods beyond
    are counted on the panel, those above with an arrow.

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
    save_figure(snapshots_figure(frames, offsets, box), path)
