"""What a run of the protocol writes while it steps: samples and checkpoints.

At every sample time the :class:`Recorder` takes one *sample*: a row of ``metrics.csv`` (the
packing's contacts, its largest contact cluster, the verdict's height kept and rods left, the
kinetic energy, the largest overlap and the step's diagnostics), a frame of
``trajectory.zarr`` and a VTK frame listed in ``trajectory.pvd``.  A *checkpoint* holds the
engine state, the samples so far and where the stepping loop stands
(:class:`~rodwarp.experiments._loop.LoopPosition`), so that a resumed run continues bit for
bit.  :func:`plot_metrics` draws ``metrics.png`` from the rows at the end.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from rodwarp.experiments import _verdict as vd
from rodwarp.rodset import contacts_per_rod, largest_cluster
from rodwarp.rodset.files import atomic_path, save_figure

#: the file a run writes when its kept stage (``Stage.keep``: the paper's entangling) ends: the
#: checkpoint at the stage boundary, kept (the rolling checkpoints are not), from which other
#: tests of the same packing start (``--entangled-from``)
ENTANGLED = "entangled.npz"
#: the array under which a checkpoint holds the kept stage's snapshot
KEPT_SNAPSHOT = "after_entangle"


class Recorder:
    """The samples of one run, the snapshots for ``snapshots.png``, and its checkpoints.

    Parameters
    ----------
    outdir : Path
        The run folder.
    model, solver : Model, RodSolver
        The engine (contacts and energies of a sample are measured with them).
    rods : RodSet
        The simulated rods (``model.rods``): the layout of every frame.
    n_frames : int
        Frames the trajectory holds at most (every sample of every stage, plus the start).
    checkpoint : (dict, dict), optional
        ``(arrays, meta)`` of the checkpoint a resumed run continues from.
    done : sequence of Stage
        With ``checkpoint``: the stages it had finished (the kept stage's snapshot comes back).
    fields_every : float
        Interval (s) of the entanglement fields: at the first sample of each such interval the
        Warp field kernels of :func:`rodwarp.analysis.compute_fields` run on the sample's rods
        (default grid, the sample's contacts) and its row gets ``cv_e``, ``mean_e`` and
        ``mean_phi``, the same numbers ``rodwarp analyze`` gives for that frame; 0: never.
    columns : callable or None
        A protocol's own columns: ``columns(model, x, control, t)`` returns a dict added to
        each row (the lab's piston height and spread radius, docs/experiments.md).
    kept_snapshot : str
        The snapshot title of the plan's kept stage (``Stage.keep``), which checkpoints carry.
    """

    def __init__(self, outdir: Path, model, solver, rods, n_frames: int, checkpoint=None, done=(),
                 fields_every: float = 0.0, columns=None, kept_snapshot: str = ""):
        from rodwarp.rodset.trajectory import Trajectory

        self.outdir = Path(outdir)
        self.model, self.solver, self.rods = model, solver, rods
        self.rows: list = []
        self.vtk: list = []  # (time, file) of every VTK frame, for trajectory.pvd
        self.snapshots = [("start", rods.points.copy())]
        self.frame = 0
        self.fields_every = float(fields_every)
        self.fields_wall_s = 0.0
        self.columns = columns
        self.kept_snapshot = kept_snapshot
        if checkpoint is not None:
            arrays, meta = checkpoint
            self.rows = meta["rows"]
            self.vtk = [tuple(e) for e in meta["vtk"]]
            self.frame = meta["frame"]
            kept = next((s for s in done if s.keep and s.snapshot), None)
            if kept is not None and KEPT_SNAPSHOT in arrays:
                self.snapshots.append((kept.snapshot, arrays[KEPT_SNAPSHOT]))
        self.trajectory = Trajectory(self.outdir / "trajectory.zarr", n_frames, rods.offsets, rods.radii,
                                     resume=checkpoint is not None)
        (self.outdir / "vtk").mkdir(exist_ok=True)

    def sample(self, stage: str, state, points, info, control, loop, test: bool) -> None:
        """Take the sample of ``state`` (the state just reached, at a sample time).

        Parameters
        ----------
        stage : str
            The stage's name.
        points : ContactPoints
            The contact points of the step that reached ``state``.
        info : StepInfo or None
            The step that reached ``state`` (None for the initial state).
        control : Control
            The stage's control (its floor is the reference of heights).
        loop : LoopPosition
            The run's position: the step count, y_c(0) and the pile at the test start.
        test : bool
            Whether the stage is the test (its samples are judged against ``loop.pile_ref``).
        """
        from rodwarp.rodset.trajectory import write_pvd, write_vtp
        from rodwarp.sim import rod_contacts

        model = self.model
        pile_ref = loop.pile_ref
        c = rod_contacts(model, state, points)
        x = state.positions()
        floor = control.floor_height(state.time)
        floor = 0.0 if floor is None else floor
        in_big = largest_cluster(model.n_rods, c)
        h = vd.centroid_height_above(x, model.mass_np, floor)
        test = test and pile_ref is not None
        self.rows.append({
            "time": state.time, "stage": stage,
            "contacts_per_rod": contacts_per_rod(model.n_rods, c),
            "largest_cluster_fraction": float(np.count_nonzero(in_big) / max(model.n_rods, 1)),
            "centroid_height": h,
            "centroid_height_ratio": h / loop.y0,
            "height_kept": h / pile_ref.height if test else "",
            "rods_left": vd.rods_left(x, model.vertex_rod_np, model.mass_np, model.n_rods, floor, in_big, pile_ref)
            if test else "",
            "kinetic_energy": self.solver.energy(state)["kinetic"],
            "max_penetration_over_d": max(0.0, -float(c.gap.min()) if len(c) else 0.0) / model.min_diameter,
            "friction_residual": info.contact_residual if info else 0.0,
            "iterations": info.iterations if info else 0,
            "dt": info.dt if info else "",
            "steps": loop.steps,
            # contact points the step solved (speculative ones included), not touching rod pairs
            "n_contact_pairs": info.n_contacts if info else 0,
            **self._fields(state.time, x, c),
            **(self.columns(self.model, x, control, state.time) if self.columns is not None else {}),
        })
        self.trajectory.write(self.frame, state.time, x)
        fname = f"vtk/frame_{self.frame:05d}.vtp"
        write_vtp(self.outdir / fname, x, self.rods.offsets, self.rods.radii, state.time)
        self.vtk.append((state.time, fname))
        write_pvd(self.outdir / "trajectory.pvd", self.vtk)
        self.frame += 1

    def _fields(self, t: float, x: np.ndarray, contacts) -> dict:
        """``cv_e``, ``mean_e`` and ``mean_phi`` of the rods at positions ``x`` when a fields
        interval starts at this sample (empty strings otherwise)."""
        import time as _time

        empty = {"cv_e": "", "mean_e": "", "mean_phi": ""}
        fe = self.fields_every
        if fe <= 0:
            return empty
        prev = self.rows[-1]["time"] if self.rows else None
        eps = 1e-9 * fe
        if prev is not None and math.floor((t + eps) / fe) == math.floor((prev + eps) / fe):
            return empty
        from rodwarp.analysis import compute_fields, field_statistics
        from rodwarp.errors import RodwarpError

        t0 = _time.perf_counter()
        rods = self.rods.with_points(x)
        rods.contacts = contacts
        try:
            st = field_statistics(compute_fields(rods, device=self.model.device), power_laws=False)
        except RodwarpError:  # no ball fits or no valid voxel (a pile spread to a monolayer)
            st = {}
        self.fields_wall_s += _time.perf_counter() - t0
        num = lambda v: "" if v is None else float(v)  # noqa: E731
        return {"cv_e": num(st.get("cv_e")), "mean_e": num(st.get("mean_e")), "mean_phi": num(st.get("mean_phi"))}

    def snapshot(self, title: str, x: np.ndarray) -> None:
        """Keep the positions ``x`` (V, 3) m for ``snapshots.png`` under ``title``."""
        self.snapshots.append((title, x))

    def checkpoint(self, state, points, loop, stage: int, j: int, mid_stage: bool, parameters: dict,
                   keep: bool = False) -> None:
        """Write a checkpoint: the engine state and its contact points (the warm start), the
        samples so far and the loop's position.

        Parameters
        ----------
        stage, j, mid_stage
            Where a resumed run starts: stage index, samples of that stage already taken, and
            whether the stage is under way (else it starts afresh).
        parameters : dict
            Every parameter of the run (a resume must repeat them).
        keep : bool
            Also write the same checkpoint to :data:`ENTANGLED`, which the rolling checkpoints
            never remove (the state when the kept stage ends).
        """
        from rodwarp.rodset.trajectory import save_checkpoint, write_checkpoint_file

        # the contact points keep the names they had inside the state, so every checkpoint loads
        arrays = {f"state_{key}": val for key, val in {**state.to_numpy(), **points.to_numpy()}.items()}
        if self.kept_snapshot:
            for title, x in self.snapshots:
                if title == self.kept_snapshot:
                    arrays[KEPT_SNAPSHOT] = x
        meta = {"stage": stage, "j": j, "mid_stage": mid_stage, "steps": loop.steps, "y0": loop.y0, "rows": self.rows,
                "pile_ref": loop.pile_ref.to_dict() if loop.pile_ref is not None else None,
                "stage_t0": loop.stage_t0, "frame": self.frame, "vtk": self.vtk,
                "parameters": json.loads(json.dumps(parameters)), "stepper": loop.stepper.to_dict(),
                "dts": loop.dts_dict(),
                "next_ck": loop.next_ck, "marks": loop.marks}
        save_checkpoint(self.outdir / "checkpoints", loop.steps, arrays, meta)
        if keep:
            write_checkpoint_file(self.outdir / ENTANGLED, arrays, meta)
        self.write_metrics()

    def write_metrics(self) -> None:
        """``metrics.csv``: one row per sample so far (written whole, atomically)."""
        with atomic_path(self.outdir / "metrics.csv") as tmp:
            with open(tmp, "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=list(self.rows[0].keys()))
                w.writeheader()
                w.writerows(self.rows)

    def finish(self) -> None:
        """Close the trajectory (consolidated metadata) once the last sample is written."""
        self.trajectory.finish()


def plot_metrics(path, rows, summary):
    """metrics.png: Z, f, height kept, rods left, y_c(t)/y_c(0), kinetic energy and the
    entanglement order parameter cv_e = sigma_e / mu_e (with the mean ACN e) against time, the
    verdict's thresholds drawn on f and h, the entangled part of the test shaded, and the
    start of the test (``summary["test_start"]["time"]``) marked dashed on every panel.

    Returns
    -------
    matplotlib.figure.Figure
        The figure written (closed in pyplot; its artists can still be read).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def col(key, sel=rows):
        return np.array([float(r[key]) if r.get(key, "") != "" else np.nan for r in sel])

    t = col("time")
    thr = summary["thresholds"]
    test = [r for r in rows if r["height_kept"] != ""]  # the test stage's judged samples
    t0 = summary["test_start"]["time"]
    tt = np.concatenate([[t0], col("time", test)])
    fig, ax = plt.subplots(4, 2, figsize=(10, 11), sharex=True)
    panels = ((ax[0, 0], t, col("contacts_per_rod"), "Z (contacts per rod)", None),
              (ax[0, 1], t, col("largest_cluster_fraction"), "f (largest cluster)", thr["cluster"]),
              (ax[1, 0], tt, np.concatenate([[1.0], col("height_kept", test)]), "height kept h = y_c(t) / y_c(t0)",
               thr["height_kept"]),
              (ax[1, 1], tt, np.concatenate([[0.0], col("rods_left", test)]), "rods left the pile (fraction)", None),
              (ax[2, 0], t, col("centroid_height_ratio"), "y_c(t) / y_c(0) (whole run)", None),
              (ax[2, 1], t, col("kinetic_energy"), "kinetic energy (J)", None),
              (ax[3, 0], t, col("cv_e"), "cv_e = sigma_e / mu_e", None),
              (ax[3, 1], t, col("mean_e"), "mean ACN e per ball", None))
    for a, x, y, label, level in panels:
        fields_panel = a in (ax[3, 0], ax[3, 1])
        a.plot(x[np.isfinite(y)], y[np.isfinite(y)], lw=1, marker="o" if fields_panel else None, ms=3)
        if fields_panel and not np.isfinite(y).any():
            a.text(0.5, 0.5, "no fields series (--fields-every 0)", transform=a.transAxes, ha="center", fontsize=8)
        a.set_ylabel(label, fontsize=9)
        a.grid(alpha=0.3)
        if level is not None:
            a.axhline(level, color="tab:red", ls=":", lw=1, label=f"threshold {level:g}")
            a.legend(fontsize=7, loc="lower left")
    for a in (ax[0, 1], ax[1, 0], ax[1, 1]):
        a.set_ylim(bottom=0)
    ax[2, 1].set_yscale("symlog", linthresh=1e-6)
    ax[2, 1].set_ylim(bottom=0)
    if test:
        ent = (col("height_kept", test) >= thr["height_kept"]) & (col("largest_cluster_fraction", test) >= thr["cluster"])
        for k in np.flatnonzero(ent):  # sample k covers the interval since the previous sample
            for a in (ax[0, 1], ax[1, 0]):
                a.axvspan(tt[k], tt[k + 1], color="tab:green", alpha=0.12, lw=0)
    if test and rows[0]["stage"] != test[0]["stage"]:  # a stage came before the test
        # the test starts at test_start (the pile reference's time), not at its first sample,
        # which comes one save interval later: the marker and its label both sit at t0
        for a in ax.ravel():
            a.axvline(t0, ls="--", lw=0.8, color="0.5")
        ax[0, 0].annotate("stability test", (t0, 0.02), xycoords=("data", "axes fraction"), fontsize=8,
                          color="0.4", xytext=(3, 0), textcoords="offset points")
    for a in ax[3]:
        a.set_xlabel("t (s)")
    fig.suptitle(f"alpha = {summary['alpha']:g}, a/g = {summary['a_over_g']:.3g}: stable = {summary['stable']} "
                 f"(h = {summary['height_kept']:.2f}, f = {summary['largest_cluster_fraction']:.2f}, "
                 f"tau = {summary['persistence']:.2f}; shaded: entangled)", fontsize=10)
    # fixed margins: tight_layout measured every label's extent and took 0.4 s of the main job
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.05, top=0.955, hspace=0.12, wspace=0.22)
    save_figure(fig, path)
    plt.close(fig)
    return fig
