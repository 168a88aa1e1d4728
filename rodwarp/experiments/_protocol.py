"""The paper's numerical experiment: random packing, entangling, vibration stability test.

Stages (seed paper, "Numerical simulations of rod packings"; docs/protocol.md):

1. random packing of N = round(5.4 alpha) straight steel rods in a 1 x 1 x 2.5 l box;
2. entangling: the closed container vibrated vertically (10 Hz, 0.05 m) for 5 s;
3. stability: side walls and lid removed, the floor vibrated at ``freq`` with ``amplitude``
   for ``duration``; f = largest contact cluster / all rods measured over time.

Stability verdict (:mod:`rodwarp.verdict`): every ``save_every`` of the test, the height
kept h(t) (mass centroid above the floor over its value at the test start), the largest
contact cluster f(t) and the rods that left the pile are recorded; ``stable`` when the
packing is still entangled (h and f above their thresholds) at the end and was entangled
for at least the threshold fraction of the test (the persistence tau).
"""

from __future__ import annotations

import csv
import json
import math
import platform
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from rodwarp.rodset.files import atomic_path, write_json
from rodwarp.errors import RodwarpError

#: contacts per rod of the paper's packings, N = round(5.4 alpha) (seed paper, "Materials and Methods")
Z_TARGET = 5.4


@dataclass
class ProtocolParams:
    """Parameters of :func:`run_protocol` (SI units; box in rod lengths)."""

    alpha: float = 100.0
    freq: float = 10.0
    amplitude: float = 0.001
    gravity: float = 0.5
    duration: float = 5.0
    entangle_duration: float = 5.0
    entangle_freq: float = 10.0
    entangle_amplitude: float = 0.05
    static_load: float = 0.0
    n_rods: int | None = None
    length: float = 1.0
    vertices: int = 10
    box: tuple = (1.0, 1.0, 2.5)
    mu: float = 0.2
    young: float = 200e9
    density: float = 7850.0
    dt: float | None = None
    iterations: int = 10
    rod_model: str = "auto"
    step_safety: float = 1.0
    rolling: bool = True
    save_every: float = 0.1
    checkpoint_every: float = 1.0
    seed: int = 0
    device: str = "auto"
    initial: str | None = None
    entangle: bool = False

    def validate(self) -> None:
        """Raise :class:`RodwarpError` (one line) for any impossible, inconsistent or oversized
        parameter, before any work (:func:`rodwarp.validation.check_protocol`); with
        ``initial`` the input rods are loaded and checked, and ``alpha`` and ``length`` are
        set from them."""
        from rodwarp.validation import check_protocol

        check_protocol(self)

    @property
    def diameter(self) -> float:
        return self.length / self.alpha

    @property
    def rods(self) -> int:
        return self.n_rods if self.n_rods is not None else int(round(Z_TARGET * self.alpha))

    @property
    def a_over_g(self) -> float:
        return 4 * math.pi**2 * self.freq**2 * self.amplitude / self.gravity


def _straight(rods, tol: float = 1e-3) -> bool:
    """Every rod's vertices (and rest vertices) lie within ``tol`` radii of its chord."""
    for pts in (rods.points, rods.rest_points):
        if pts is None:
            continue
        off = rods.offsets
        rid = np.repeat(np.arange(rods.n_rods), np.diff(off))
        p0, p1 = pts[off[:-1]], pts[off[1:] - 1]
        chord = p1 - p0
        dev = np.linalg.norm(np.cross(pts - p0[rid], chord[rid]), axis=1) / np.linalg.norm(chord, axis=1)[rid]
        if np.any(dev > tol * rods.radii[rid]):
            return False
    return True


def _versions() -> dict:
    import warp

    import rodwarp

    return {"rodwarp": rodwarp.__version__, "warp": warp.config.version, "numpy": np.__version__,
            "python": platform.python_version(), "platform": platform.platform()}


#: rigid rods when the self-weight sag of a simply supported rod, 5 q l^4 / (384 E I), is below
#: this fraction of a diameter (the knee of benchmarks/bench_rigid.py; docs/engine.md)
RIGID_SAG = 0.01


def rod_model_rule(params: ProtocolParams) -> dict:
    """Which rod model the experiment uses and why.

    ``auto`` picks rigid rods when their bending under the scene's largest static load, the
    self-weight sag 5 q l^4 / (384 E I) of a simply supported rod with q = rho A g_eff
    (static load included), is below ``RIGID_SAG`` diameters; elastic otherwise, and always
    for an input with curved rods (rigid rods must be straight).

    Returns
    -------
    dict
        ``rod_model`` (the choice), ``requested``, ``sag_over_d``, ``threshold`` and ``rule``.
    """
    d = params.diameter
    r = d / 2
    g_eff = params.gravity * (1.0 + 4.0 * params.static_load / math.pi)
    q = params.density * math.pi * r**2 * g_eff
    EI = params.young * math.pi * r**4 / 4
    sag = 5 * q * params.length**4 / (384 * EI) / d
    choice = params.rod_model
    if choice == "auto":
        choice = "rigid" if sag < RIGID_SAG else "elastic"
    return {"rod_model": choice, "requested": params.rod_model, "sag_over_d": sag, "threshold": RIGID_SAG,
            "rule": f"rigid when the self-weight sag 5 q l^4 / (384 E I) < {RIGID_SAG:g} d, else elastic"}


def _build(params: ProtocolParams, rods, device, rod_model: str):
    """Model and solver of the experiment (deterministic given the parameters and rods)."""
    from rodwarp.sim import Material, Model, RodSolver

    g_eff = params.gravity * (1.0 + 4.0 * params.static_load / math.pi)
    model = Model(rods, Material(params.young, params.density), gravity=(0.0, 0.0, -g_eff), mu=params.mu,
                  rod_model=rod_model, rolling=params.rolling, device=device)
    bb = rods.bounding_box()
    if rods.box is not None:
        # the input's container, widened to its rods: rods lying on (or sunk into) the box's
        # floor get the floor under their lowest point, never a floor above it
        lo = np.minimum(np.asarray(rods.box[0], float), bb[0])
        hi = np.maximum(np.asarray(rods.box[1], float), bb[1])
    else:  # an input without a container: the floor under its lowest point, walls around it
        lo, hi = bb[0], bb[1]
    model.add_box(lo, hi + np.array([0, 0, 0.5 * params.length]), walls=("floor", *SIDE_WALLS), moving=True)
    return model, RodSolver(model, iterations=params.iterations), (lo, hi)


#: walls removed for the stability test (the floor stays and vibrates)
SIDE_WALLS = ("ceiling", "x-", "x+", "y-", "y+")


def stage_control(model, name: str, amp: float, freq: float, t0: float):
    """Control of a stage: entangling in the closed container, the stability test on the floor alone."""
    control = model.control()
    if name == "stability":
        control.remove_walls(SIDE_WALLS)
    control.set_drive(amp, freq, phase_time=t0)
    return control


def _default_dt(params: ProtocolParams, model, solver) -> float:
    """One step for the whole run: the smaller of the solver's defaults under the entangling
    and the stability-test drives (s).

    The stability test alone would allow a step set by its drive (1/(40 f)), but a pile
    resting under gravity needs the finer step of the entangling stage to keep Gauss-Seidel
    converged: at alpha = 100, f = 10 Hz, 2.5e-3 s let rods overlap by 0.25 d (the run was
    stopped) where 1e-3 s kept the largest overlap at 0.015 d for less total cost.
    """
    return min(solver.default_dt(stage_control(model, "entangle", params.entangle_amplitude, params.entangle_freq,
                                               0.0)),
               solver.default_dt(stage_control(model, "stability", params.amplitude, params.freq, 0.0)))


def _stages(params: ProtocolParams):
    stages = []
    if params.entangle_duration > 0 and (not params.initial or params.entangle):
        stages.append(("entangle", params.entangle_duration, params.entangle_amplitude, params.entangle_freq))
    stages.append(("stability", params.duration, params.amplitude, params.freq))
    return stages


def run_protocol(params: ProtocolParams, outdir, *, progress: bool = True, resume: bool = False,
                 overwrite: bool = False, thresholds=None) -> dict:
    """Run the whole experiment and write its outputs to ``outdir``.

    Writes ``summary.json`` (every parameter, seed, versions, device, dt, steps, wall time and
    the results), ``metrics.csv`` (time series), ``trajectory.zarr`` (frames every
    ``save_every`` s), ``trajectory.pvd`` with ``vtk/`` (ParaView), ``initial.npz`` and
    ``final.npz`` (rod sets, the final one with contacts), ``metrics.png`` and
    ``snapshots.png``; checkpoints every ``checkpoint_every`` s of simulated time in
    ``checkpoints/``. With ``resume`` the run continues from the newest checkpoint and ends in
    the same final state, bit for bit on the CPU, as an uninterrupted run.

    The run owns ``outdir`` through ``rodwarp-run.json`` (:mod:`rodwarp.rundir`): a folder
    holding another run is refused unless ``overwrite`` (which removes the old outputs first).

    ``thresholds`` (:class:`rodwarp.verdict.Thresholds`, default the measured ones) set the
    stability verdict; summary.json records them with the rule.

    Returns
    -------
    dict
        The summary.
    """
    from rodwarp import _warp
    from rodwarp import verdict as vd
    from rodwarp.metrics import centroid_height, contacts_per_rod, largest_cluster, rod_contacts
    from rodwarp.sim.state import State
    from rodwarp.rodset.trajectory import (Trajectory, latest_checkpoint, plot_snapshots, save_checkpoint, write_pvd,
                                           write_vtp)
    from rodwarp.packing import orientation_statistics, random_packing
    from rodwarp.rodset import load

    from rodwarp import rundir
    from rodwarp.validation import check_step_count, output_bytes

    params.validate()
    thresholds = thresholds or vd.DEFAULT_THRESHOLDS
    outdir = Path(outdir)
    run = rundir.claim(outdir, "simulate", asdict(params), rundir.SIMULATE_OUTPUTS, resume=resume,
                       overwrite=overwrite, resumable=any((outdir / "checkpoints").glob("ckpt_*.npz")),
                       need_bytes=output_bytes(params))
    device = _warp.resolve_device(params.device)
    t_wall = time.perf_counter()
    ckdir = outdir / "checkpoints"
    ck = None
    if resume:
        ck = latest_checkpoint(ckdir)
        if ck is None:
            raise RodwarpError(f"nothing to resume: no checkpoint in {ckdir}; run without --resume")
        saved = ck[1]["parameters"]
        mine = {k: v for k, v in asdict(params).items() if k != "device"}
        theirs = {k: v for k, v in saved.items() if k != "device"}
        if json.loads(json.dumps(mine)) != theirs:
            diff = sorted(k for k in mine if json.loads(json.dumps(mine[k])) != theirs.get(k))
            raise RodwarpError(f"--resume with different parameters than the checkpoint ({', '.join(diff)}); "
                               f"repeat the original command with --resume")
        rods = load(outdir / "initial.npz")
    elif params.initial:
        rods = params._input_rods  # loaded, in metres, and checked by validate()
    else:
        rods = random_packing(params.rods, params.length, params.diameter, np.asarray(params.box) * params.length,
                              n_vertices=params.vertices, seed=params.seed, device=device)
    if not resume:
        for old in ckdir.glob("ckpt_*.npz"):
            old.unlink()
        rods.save(outdir / "initial.npz")
    orient = orientation_statistics(rods)
    rule = rod_model_rule(params)
    if rule["rod_model"] == "rigid" and params.rod_model == "auto" and not _straight(rods):
        rule.update(rod_model="elastic", rule=rule["rule"] + " (the input has curved rods: elastic)")
    model, solver, (box_lo, box_hi) = _build(params, rods, device, rule["rod_model"])
    sim_rods = model.rods  # the simulated rods (two vertices per rod for rigid rods)
    stages = _stages(params)
    protocol_dt = _default_dt(params, model, solver)
    check_step_count(params, params.dt or protocol_dt, "--dt" if params.dt else "the default step")
    control = None

    state = model.state()
    other = State(model)
    floor0 = model.control().floor_height(0.0)
    y0 = centroid_height(model, state, 0.0 if floor0 is None else floor0)
    pile_ref = None  # the pile at the start of the stability test (reference of h and rods left)
    rows: list = []
    steps = 0
    dts: dict = {}
    stage_t0 = {}
    start_stage, start_j, mid_stage = 0, 0, False
    # the adaptive step's memory: last step and fastest vertex (checkpointed: resume is bit-exact)
    stepper = {"dt": None, "vmax": float(np.linalg.norm(state.velocities(), axis=1).max(initial=0.0))}
    next_ck = params.checkpoint_every
    last_info = None
    vtk_entries: list = []
    snaps = [("start", sim_rods.points.copy())]
    if ck is not None:
        arrays, meta = ck
        rows = meta["rows"]
        y0 = meta["y0"]
        pile_ref = vd.PileReference.from_dict(meta["pile_ref"]) if meta.get("pile_ref") else None
        steps = meta["steps"]
        stage_t0 = {k: float(v) for k, v in meta["stage_t0"].items()}
        start_stage, start_j, mid_stage = meta["stage"], meta["j"], meta["mid_stage"]
        stepper = dict(meta["stepper"])
        dts = meta["dts"]
        next_ck = float(meta["next_ck"])
        vtk_entries = [tuple(e) for e in meta["vtk"]]
        for name in [s[0] for s in stages[:start_stage]]:
            if name == "entangle" and "after_entangle" in arrays:
                snaps.append(("after entangling", arrays["after_entangle"]))
        if mid_stage:
            name, dur, amp, freq = stages[start_stage]
            control = stage_control(model, name, amp, freq, stage_t0[name])
        state.load_numpy({k[6:]: v for k, v in arrays.items() if k.startswith("state_")})

    frames_per = {}
    for name, dur, amp, freq in stages:
        frames_per[name] = int(math.ceil(dur / params.save_every)) + 1
    traj = Trajectory(outdir / "trajectory.zarr", 1 + sum(frames_per.values()), sim_rods.offsets, sim_rods.radii,
                      resume=ck is not None)
    frame = ck[1]["frame"] if ck is not None else 0
    (outdir / "vtk").mkdir(exist_ok=True)

    def sample(stage, st, inf):
        nonlocal frame
        c = rod_contacts(model, st)
        x = st.positions()
        floor = control.floor_height(st.time)
        floor = 0.0 if floor is None else floor
        in_big = largest_cluster(model.n_rods, c)
        h = vd.centroid_height_above(x, model.mass_np, floor)
        test = stage == "stability" and pile_ref is not None
        rows.append({
            "time": st.time, "stage": stage,
            "contacts_per_rod": contacts_per_rod(model.n_rods, c),
            "largest_cluster_fraction": float(np.count_nonzero(in_big) / max(model.n_rods, 1)),
            "centroid_height": h,
            "centroid_height_ratio": h / y0,
            "height_kept": h / pile_ref.height if test else "",
            "rods_left": vd.rods_left(x, model.vertex_rod_np, model.mass_np, model.n_rods, floor, in_big, pile_ref)
            if test else "",
            "kinetic_energy": solver.energy(st)["kinetic"],
            "max_penetration_over_d": max(0.0, -float(c.gap.min()) if len(c) else 0.0) / model.min_diameter,
            "friction_residual": inf.contact_residual if inf else 0.0,
            "iterations": inf.iterations if inf else 0,
            "dt": inf.dt if inf else "",
            "steps": steps,
            "n_contact_pairs": inf.n_contacts if inf else 0,
        })
        traj.write(frame, st.time, x)
        fname = f"vtk/frame_{frame:05d}.vtp"
        write_vtp(outdir / fname, x, sim_rods.offsets, sim_rods.radii, st.time)
        vtk_entries.append((st.time, fname))
        write_pvd(outdir / "trajectory.pvd", vtk_entries)
        frame += 1

    def checkpoint(si, j, mid):
        arrays = {f"state_{key}": val for key, val in state.to_numpy().items()}
        for title, x in snaps:
            if title == "after entangling":
                arrays["after_entangle"] = x
        meta = {"stage": si, "j": j, "mid_stage": mid, "steps": steps, "y0": y0, "rows": rows,
                "pile_ref": pile_ref.to_dict() if pile_ref is not None else None, "stage_t0": stage_t0, "frame": frame,
                "vtk": vtk_entries, "parameters": json.loads(json.dumps(asdict(params))), "stepper": stepper,
                "dts": dts, "next_ck": next_ck}
        save_checkpoint(ckdir, steps, arrays, meta)
        _write_metrics(outdir / "metrics.csv", rows)

    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    total = sum(s[1] for s in stages)
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("t={task.completed:.2f}/{task.total:.2f} s"),
                  TextColumn("{task.fields[rate]}"), TimeRemainingColumn(), disable=not progress) as bar:
        task = bar.add_task("simulate", total=total, rate="")
        t_done = 0.0
        for si, (name, dur, amp, freq) in enumerate(stages):
            if si < start_stage:
                t_done += dur
                continue
            j0 = start_j if si == start_stage else 0  # samples of this stage already taken
            if si != start_stage or not mid_stage:
                stage_t0[name] = state.time
                control = stage_control(model, name, amp, freq, state.time)
                dts[name] = {"steps": 0, "min": None, "max": None, "mean": None, "sum": 0.0}
                next_ck = state.time + params.checkpoint_every
                if name == "stability":
                    state.wall_impulse.zero_()
                    floor = control.floor_height(state.time)
                    pile_ref = vd.pile_reference(state.time, state.positions(), model.vertex_rod_np, model.mass_np,
                                                 model.n_rods, 0.0 if floor is None else floor,
                                                 float(np.max(rods.rod_lengths())), model.min_diameter)
            t_s0 = stage_t0[name]
            t_end = t_s0 + dur
            n_samples = max(1, int(math.ceil(dur / params.save_every - 1e-9)))
            bar.update(task, description=name, completed=t_done + (state.time - t_s0))
            if si == 0 and j0 == 0 and not mid_stage:
                sample(name, state, None)
            t0 = time.perf_counter()
            steps0 = steps
            j = j0 + 1
            while j <= n_samples:
                target = t_end if j == n_samples else t_s0 + j * params.save_every
                dt = params.dt or solver.adaptive_dt(control, stepper["vmax"], stepper["dt"],
                                                     safety=params.step_safety)
                left = target - state.time
                # reach the sample time exactly, in equal steps no longer than dt
                n_left = max(1, int(math.ceil(left / dt - 1e-6)))
                landing = n_left == 1
                dt = left / n_left
                info = solver.step(state, other, control, dt)
                state, other = other, state
                if landing:
                    state.time = target
                steps += 1
                st = dts[name]
                st["steps"] += 1
                st["sum"] += dt
                st["min"] = dt if st["min"] is None else min(st["min"], dt)
                st["max"] = dt if st["max"] is None else max(st["max"], dt)
                stepper["vmax"] = info.max_speed
                stepper["dt"] = dt
                last_info = info
                if landing:
                    sample(name, state, info)
                    j += 1
                    rate = (steps - steps0) / max(time.perf_counter() - t0, 1e-9)
                    bar.update(task, completed=t_done + (state.time - t_s0), rate=f"{rate:.0f} steps/s")
                if state.time >= next_ck - 1e-12 and j <= n_samples:
                    next_ck += params.checkpoint_every
                    checkpoint(si, j - 1, True)
            t_done += dur
            dts[name]["mean"] = dts[name]["sum"] / max(dts[name]["steps"], 1)
            if name == "entangle":
                snaps.append(("after entangling", state.positions()))
            if si + 1 < len(stages):
                next_ck = state.time + params.checkpoint_every
                checkpoint(si + 1, 0, False)

    wall = time.perf_counter() - t_wall
    c = rod_contacts(model, state)
    final = sim_rods.with_points(state.positions(), velocities=state.velocities())
    final.contacts = c
    final.attrs.update({"time": state.time})
    final.save(outdir / "final.npz")
    snaps.append(("end", state.positions()))
    plot_snapshots(outdir / "snapshots.png", snaps, sim_rods.offsets, box=(box_lo, box_hi))

    verdict = vd.judge_rows(rows, pile_ref.time, thresholds).to_dict()
    summary = {
        "alpha": params.alpha, "diameter": params.diameter, "length": params.length,  # measured for --initial
        "n_rods": model.n_rods, "freq": params.freq, "amplitude": params.amplitude,
        "gravity": params.gravity, "a_over_g": params.a_over_g, "static_load": params.static_load,
        "contacts_per_rod": contacts_per_rod(model.n_rods, c),
        "largest_cluster_fraction": verdict["largest_cluster_fraction"],
        "height_kept": verdict["height_kept"], "persistence": verdict["persistence"],
        "rods_left": verdict["rods_left"], "stable": verdict["stable"], "thresholds": verdict["thresholds"],
        "stable_rule": verdict["rule"], "test_start": pile_ref.to_dict(),
        "centroid_height_ratio": centroid_height(model, state, 0.0 if control.floor_height(state.time) is None
                                                 else control.floor_height(state.time)) / y0,
        "max_penetration_over_d": max(r["max_penetration_over_d"] for r in rows),
        "rod_model": rule["rod_model"], "rod_model_rule": rule,
        "seed": params.seed, "device": device, "dt": dts, "steps": steps, "wall_time_s": wall,
        "resumed": bool(resume), "initial_orientation": orient,
        "parameters": asdict(params), "versions": _versions(),
    }
    _write_metrics(outdir / "metrics.csv", rows)
    write_json(outdir / "summary.json", summary)
    _plot_metrics(outdir / "metrics.png", rows, summary)
    traj.finish()
    run.complete()
    return summary


def _write_metrics(path, rows):
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0].keys()))
            w.writeheader()
            w.writerows(rows)


def _plot_metrics(path, rows, summary):
    """metrics.png: Z, f, height kept, rods left, y_c(t)/y_c(0) and kinetic energy against time,
    the verdict's thresholds drawn on f and h, the entangled part of the test shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def col(key, sel=rows):
        return np.array([float(r[key]) if r[key] != "" else np.nan for r in sel])

    t = col("time")
    thr = summary["thresholds"]
    test = [r for r in rows if r["stage"] == "stability" and r["height_kept"] != ""]
    t0 = summary["test_start"]["time"]
    tt = np.concatenate([[t0], col("time", test)])
    fig, ax = plt.subplots(3, 2, figsize=(10, 8.5), sharex=True)
    panels = ((ax[0, 0], t, col("contacts_per_rod"), "Z (contacts per rod)", None),
              (ax[0, 1], t, col("largest_cluster_fraction"), "f (largest cluster)", thr["cluster"]),
              (ax[1, 0], tt, np.concatenate([[1.0], col("height_kept", test)]), "height kept h = y_c(t) / y_c(t0)",
               thr["height_kept"]),
              (ax[1, 1], tt, np.concatenate([[0.0], col("rods_left", test)]), "rods left the pile (fraction)", None),
              (ax[2, 0], t, col("centroid_height_ratio"), "y_c(t) / y_c(0) (whole run)", None),
              (ax[2, 1], t, col("kinetic_energy"), "kinetic energy (J)", None))
    for a, x, y, label, level in panels:
        a.plot(x, y, lw=1)
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
    t_stab = [r["time"] for r in rows if r["stage"] == "stability"]
    if t_stab and any(r["stage"] == "entangle" for r in rows):
        for a in ax.ravel():
            a.axvline(t0, ls="--", lw=0.8, color="0.5")
        ax[0, 0].annotate("stability test", (t_stab[0], 0.02), xycoords=("data", "axes fraction"), fontsize=8,
                          color="0.4", xytext=(3, 0), textcoords="offset points")
    for a in ax[2]:
        a.set_xlabel("t (s)")
    fig.suptitle(f"alpha = {summary['alpha']:g}, a/g = {summary['a_over_g']:.3g}: stable = {summary['stable']} "
                 f"(h = {summary['height_kept']:.2f}, f = {summary['largest_cluster_fraction']:.2f}, "
                 f"tau = {summary['persistence']:.2f}; shaded: entangled)", fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
