"""Run outputs: trajectory (zarr), ParaView series (VTK polylines), checkpoints, snapshots.

Every writer is crash-safe: single files are written atomically (write, then rename), and
the trajectory records how many frames are complete only after a frame is written, so a
kill at any moment leaves every earlier frame, metric and checkpoint readable.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from rodwarp.atomic import atomic_path, write_text


class Trajectory:
    """Frames of vertex positions in ``trajectory.zarr`` (one chunk per frame).

    Arrays: ``positions`` (F, V, 3) float64 m, ``time`` (F,) s; attributes ``n_frames``
    (frames complete), ``offsets`` and ``radii`` (the rod layout), ``units`` = "m".
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
            self.group = zarr.open_group(str(self.path), mode="w")
            self.group.create_array("positions", shape=(n_frames_max, V, 3), chunks=(1, V, 3), dtype="f8",
                                    fill_value=np.nan)
            self.group.create_array("time", shape=(n_frames_max,), chunks=(max(n_frames_max, 1),), dtype="f8",
                                    fill_value=np.nan)
            self.group.attrs.update({"n_frames": 0, "offsets": np.asarray(offsets).tolist(),
                                     "radii": np.asarray(radii).tolist(), "units": "m",
                                     "axes": "frame, vertex, xyz"})

    @property
    def n_frames(self) -> int:
        return int(self.group.attrs["n_frames"])

    def write(self, index: int, t: float, positions: np.ndarray) -> None:
        """Write frame ``index`` and only then count it as complete."""
        self.group["positions"][index] = positions
        times = self.group["time"][:]
        times[index] = t
        self.group["time"][:] = times
        self.group.attrs["n_frames"] = index + 1


def write_vtp(path, positions: np.ndarray, offsets: np.ndarray, radii: np.ndarray, t: float) -> None:
    """One frame as VTK XML PolyData: a polyline per rod, ``radius`` per point (ParaView: Tube filter)."""
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
    write_text(path, text)


def write_pvd(path, entries) -> None:
    """ParaView collection of (time, file) pairs: open this file to play the run."""
    rows = "\n".join(f'  <DataSet timestep="{t:.9g}" part="0" file="{f}"/>' for t, f in entries)
    write_text(path, f'<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n <Collection>\n{rows}\n'
                     f' </Collection>\n</VTKFile>\n')


def save_checkpoint(directory, step: int, arrays: dict, meta: dict, keep: int = 2) -> Path:
    """Write ``ckpt_<step>.npz`` atomically (arrays plus JSON ``meta``); keep the newest ``keep``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"ckpt_{step:010d}.npz"
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, meta=np.array(json.dumps(meta)), **arrays)
    for old in sorted(directory.glob("ckpt_*.npz"))[:-keep]:
        old.unlink(missing_ok=True)
    return path


def latest_checkpoint(directory):
    """(arrays, meta) of the newest readable checkpoint in ``directory``, or None."""
    for path in sorted(Path(directory).glob("ckpt_*.npz"), reverse=True):
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                arrays = {k: z[k] for k in z.files if k != "meta"}
            return arrays, meta
        except Exception:
            continue  # a torn file cannot exist (atomic writes), but skip anything unreadable
    return None


def plot_snapshots(path, frames, offsets, box=None) -> None:
    """Side views (x-z) of the packing at the given (title, positions) frames, as one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    fig, axes = plt.subplots(1, len(frames), figsize=(3.2 * len(frames), 5.5), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, (title, x) in zip(axes, frames):
        segs = [x[offsets[r]:offsets[r + 1]][:, [0, 2]] for r in range(len(offsets) - 1)]
        ax.add_collection(LineCollection(segs, linewidths=0.6, colors="0.2"))
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.autoscale()
        if box is not None:
            ax.add_patch(plt.Rectangle((box[0][0], box[0][2]), box[1][0] - box[0][0], box[1][2] - box[0][2],
                                       fill=False, ls="--", lw=0.6, color="tab:blue"))
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("z (m)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
