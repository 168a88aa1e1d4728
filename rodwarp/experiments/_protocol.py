"""The paper's numerical experiment: random packing, entangling, vibration stability test.

Stages (the seed paper's "Numerical simulations of rod packings"; docs/protocol.md):

1. random packing of N = round(5.4 alpha) straight steel rods in a 1 x 1 x 2.5 l box;
2. entangling: the closed container vibrated vertically (10 Hz, 0.05 m) for 5 s;
3. stability: side walls and lid removed, the floor vibrated at ``freq`` with ``amplitude``
   for ``duration``; f = largest contact cluster / all rods measured over time.

The stages are a run plan (:func:`rodwarp.experiments._plan.plan`) stepped by one loop
(:func:`run_protocol`): each stage is a drive and a set of walls (``Stage.control``) on the
same model and states; the loop takes adaptive steps that
land exactly on the sample times, and a :class:`~rodwarp.experiments._recorder.Recorder` takes
the samples (metrics row, trajectory and VTK frames) and the checkpoints, which also hold the
loop's own position (:class:`LoopPosition`), so a resumed run is bit-identical.

Stability verdict (:mod:`rodwarp.experiments._verdict`, docs/verdict.md): every
``save_every`` of the test, the height kept h(t) (mass centroid above the floor over its
value at the test start), the largest contact cluster f(t) and the rods that left the pile
are recorded; ``stable`` when the packing is still entangled (h and f above their thresholds)
at the end and was entangled for at least the threshold fraction of the test (the
persistence tau).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from rodwarp.errors import RodwarpError

from rodwarp.experiments._outputs import SIMULATE_OUTPUTS  # noqa: E402
from rodwarp.experiments._plan import ENTANGLE, SIDE_WALLS, frames, plan  # noqa: E402

from rodwarp.experiments._params import (RIGID_SAG, RODS_PER_ALPHA, ProtocolParams, _straight,  # noqa: E402,F401
                                         option_table, rod_model_rule, rod_resolution)


def _build(params: ProtocolParams, rods, device, rod_model: str):
    """Model and solver of the experiment (deterministic given the parameters and rods)."""
    from rodwarp.sim import Material, ModelBuilder, RodSolver

    g_eff = params.effective_gravity
    builder = ModelBuilder(rods, Material(params.young, params.density), gravity=(0.0, 0.0, -g_eff), mu=params.mu,
                           rod_model=rod_model, rolling=params.spin, contact_law=params.contact_law_object(),
                           device=device)
    from rodwarp.experiments._protocols import plugin

    if (proto := plugin(params.protocol)) is not None:
        box = proto.walls(builder, params, rods)
        model = builder.finalize()
        return model, RodSolver(model, iterations=params.iterations, steps_per_period=params.steps_per_period), box
    bb = rods.bounding_box()
    if rods.box is not None:
        # the input's container, widened to its rods: rods lying on (or sunk into) the box's
        # floor get the floor under their lowest point, never a floor above it
        lo = np.minimum(np.asarray(rods.box[0], float), bb[0])
        hi = np.maximum(np.asarray(rods.box[1], float), bb[1])
    else:  # an input without a container: the floor under its lowest point, walls around it
        lo, hi = bb[0], bb[1]
    builder.add_box(lo, hi + np.array([0, 0, 0.5 * params.length]), walls=("floor", *SIDE_WALLS), moving=True)
    model = builder.finalize()
    return model, RodSolver(model, iterations=params.iterations, steps_per_period=params.steps_per_period), (lo, hi)


#: walls removed for the stability test (the floor stays and vibrates; docs/protocol.md)
def _check_plan(stages):
    """Refuse a plan without exactly one test stage or with a name twice (one line)."""
    names = [s.name for s in stages]
    if sum(s.test for s in stages) != 1:
        raise RodwarpError(f"a run plan needs exactly one test stage (Stage(test=True)); got {names}")
    if len(set(names)) != len(names):
        raise RodwarpError(f"stage names must be unique in a run plan; got {names}")
    return stages


def _default_dt(stages, model, solver) -> float:
    """The worst-case step of the run (s): the smallest of the solver's default steps under the
    drives of its stages, at the scene's characteristic speed.

    A run takes adaptive steps (:meth:`RodSolver.adaptive_dt`); this step only sizes the run
    before it starts (:func:`~rodwarp.experiments._checks.check_step_count` refuses a run of
    too many steps). It was the fixed step of the run before the adaptive one: the stability
    test alone would allow a step set by its drive (1/(40 f)), but a pile resting under
    gravity needs the finer step of the entangling stage to keep Gauss-Seidel converged (at
    alpha = 100, f = 10 Hz, 2.5e-3 s let rods overlap by 0.25 d where 1e-3 s kept the largest
    overlap at 0.015 d).
    """
    return min(solver.default_dt(stage.control(model, 0.0)) for stage in stages)


@dataclass
class LoopPosition:
    """Where the stepping loop stands: what a checkpoint restores besides the engine state and
    the samples (those are the :class:`~rodwarp.experiments._recorder.Recorder`'s).

    Attributes
    ----------
    start_stage, start_j, mid_stage
        Where the loop starts: the stage index, the samples of that stage already taken, and
        whether that stage is under way (a resumed run) or starts afresh.
    steps : int
        Steps taken so far.
    y0 : float
        Mass centroid height above the floor at t = 0 (m), the reference of y_c(t)/y_c(0).
    pile_ref : PileReference or None
        The pile when the stability test started (the verdict's reference).
    stage_t0 : dict
        Start time of each stage begun (s).
    stepper : dict
        The adaptive step's memory: the last step ``dt`` (s) and the fastest vertex speed
        ``vmax`` (m/s) after it; checkpointed, so a resumed run picks the same steps.
    dts : dict
        Per stage: step count, min, max, mean and sum of the steps (s), for summary.json.
    next_ck : float
        Simulated time of the next checkpoint (s).
    marks : dict
        What stages measured for later ones and for summary.json (the lab's packing height
        when pressing began, ``height0``; its results at each strain, ``strains``).
    """

    y0: float
    stepper: dict
    next_ck: float
    steps: int = 0
    pile_ref: object = None
    stage_t0: dict = field(default_factory=dict)
    dts: dict = field(default_factory=dict)
    start_stage: int = 0
    start_j: int = 0
    mid_stage: bool = False
    marks: dict = field(default_factory=dict)

    @classmethod
    def from_checkpoint(cls, meta: dict) -> "LoopPosition":
        from rodwarp.experiments._verdict import PileReference

        return cls(y0=meta["y0"], stepper=dict(meta["stepper"]), next_ck=float(meta["next_ck"]), steps=meta["steps"],
                   pile_ref=PileReference.from_dict(meta["pile_ref"]) if meta.get("pile_ref") else None,
                   stage_t0={k: float(v) for k, v in meta["stage_t0"].items()}, dts=meta["dts"],
                   start_stage=meta["stage"], start_j=meta["j"], mid_stage=meta["mid_stage"],
                   marks=dict(meta.get("marks", {})))


def _resume_point(params: ProtocolParams, ckdir: Path):
    """The newest checkpoint ``(arrays, meta)`` of this run, refused when it has other parameters."""
    from rodwarp.rodset.trajectory import latest_checkpoint

    ck = latest_checkpoint(ckdir)
    if ck is None:
        raise RodwarpError(f"nothing to resume: no checkpoint in {ckdir}; run without --resume")
    saved = ck[1]["parameters"]
    # a parameter left at None equals one absent from an older checkpoint (fields added since)
    mine = {k: v for k, v in _effective(asdict(params)).items() if k != "device" and v is not None}
    theirs = {k: v for k, v in _effective(saved).items() if k != "device" and v is not None}
    if json.loads(json.dumps(mine)) != theirs:
        m = json.loads(json.dumps(mine))
        diff = sorted(k for k in set(m) | set(theirs) if m.get(k) != theirs.get(k))
        said = ", ".join(f"{k} {theirs.get(k)} in the checkpoint, {m.get(k)} now" for k in diff)
        raise RodwarpError(f"--resume with different parameters than the checkpoint ({said}); repeat the original "
                           f"command with --resume, giving these as the checkpoint has them (a default may have "
                           f"changed since: CHANGELOG.md)")
    return ck


#: the file a run writes when its entangling stage ends: the checkpoint at the stage boundary,
#: kept (the rolling checkpoints are not), from which other stability tests of the same
#: entangled packing start (``entangled_from``)
ENTANGLED = "entangled.npz"
#: the stability test's own parameters: a run may take its entangled packing from a run that
#: differs from it in these alone (and in the device)
TEST_FIELDS = ("freq", "amplitude", "duration")


def _comparable(parameters: dict) -> dict:
    """The parameters that fix the packing and its entangling (JSON round trip, so tuples
    compare equal to the lists a checkpoint holds)."""
    # None equals absent: a donor written before a field was added still matches
    return {k: v for k, v in json.loads(json.dumps(_effective(parameters))).items()
            if k not in (*TEST_FIELDS, "device") and v is not None}


def _effective(parameters: dict) -> dict:
    """Parameters with the defaults that depend on others filled in (rolling on unless the
    contact law is IMC; the exact law as absent), so that a run written before these options
    existed (rolling True, no contact law) compares equal to today's defaults."""
    out = dict(parameters)
    imc = out.get("contact_law") == "imc"
    if out.get("rolling") is None:
        out["rolling"] = not imc
    if out.get("contact_law") == "exact":
        out["contact_law"] = None
    # before issue 45 every drive took at least 40 steps a period, and every rod 10 vertices
    # unless given: a checkpoint of then compares by what it ran with, a run of now by the
    # resolution rule's count
    if out.get("steps_per_period") is None:
        out["steps_per_period"] = 40.0
    if out.get("vertices") is None:
        known = ProtocolParams.__dataclass_fields__
        out["vertices"] = ProtocolParams(**{k: tuple(v) if isinstance(v, list) else v for k, v in out.items()
                                            if k in known}).n_vertices
    return out


def check_branch_protocol(params: ProtocolParams) -> None:
    """Refuse ``--entangled-from`` for a protocol without an entangling stage (one line)."""
    if params.protocol != "paper":
        raise RodwarpError(f"--entangled-from applies only with --protocol paper (it starts the stability test "
                           f"from another run's entangled packing); --protocol {params.protocol} pours its packing "
                           f"and has no entangling stage: drop --entangled-from")


def _entangled_point(params: ProtocolParams, donor: Path, outdir: Path):
    """``(arrays, meta)`` of ``donor``'s end-of-entangling checkpoint, refused (one line) when
    it is missing, unreadable, or of another packing or entangling than ``params``."""
    from rodwarp.rodset.trajectory import read_checkpoint_file

    check_branch_protocol(params)
    if plan(params)[0].name != ENTANGLE:
        raise RodwarpError("--entangled-from: this run has no entangling stage (entangle duration 0, or --initial "
                           "without --entangle); drop --entangled-from")
    if donor.resolve() == outdir.resolve():
        raise RodwarpError(f"--entangled-from {donor} is this run's own --out; give the folder of another run")
    path = donor / ENTANGLED
    if not path.is_file():
        raise RodwarpError(f"--entangled-from {donor}: no {ENTANGLED} there (a simulate run writes it when its "
                           f"entangling stage ends); run that simulation first or drop --entangled-from")
    try:
        arrays, meta = read_checkpoint_file(path)
        if meta["stage"] != 1 or meta["mid_stage"]:
            raise ValueError("not an end-of-entangling checkpoint")
    except Exception as e:  # noqa: BLE001 - a damaged or foreign file: one line, not a traceback
        raise RodwarpError(f"--entangled-from {donor}: {ENTANGLED} is unreadable ({type(e).__name__}: {e}); "
                           "run that simulation again") from None
    mine, theirs = _comparable(asdict(params)), _comparable(meta["parameters"])
    diff = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
    if diff:
        raise RodwarpError(f"--entangled-from {donor}: that run's packing or entangling differs from this one "
                           f"({', '.join(diff)}); only {', '.join(TEST_FIELDS)} may differ")
    for name in ("initial.npz", "trajectory.zarr"):
        if not (donor / name).exists():
            raise RodwarpError(f"--entangled-from {donor}: its {name} is missing; run that simulation again")
    return arrays, meta


def _copy_file(src: Path, dst: Path) -> None:
    """Copy ``src`` to ``dst`` atomically (write, then rename)."""
    import shutil

    from rodwarp.rodset.files import atomic_path

    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def _take_entangling(donor: Path, outdir: Path, meta: dict, n_frames: int, rods) -> None:
    """Copy ``donor``'s outputs of the entangling stage into ``outdir``: its VTK frames and the
    trajectory frames up to the stage boundary (a fresh trajectory of this run's length)."""
    import zarr

    from rodwarp.rodset.trajectory import Trajectory

    n = int(meta["frame"])
    src = zarr.open_group(str(donor / "trajectory.zarr"), mode="r")
    if int(src.attrs.get("n_frames", 0)) < n:
        raise RodwarpError(f"--entangled-from {donor}: its trajectory holds {src.attrs.get('n_frames', 0)} of the "
                           f"{n} frames of its entangling stage; run that simulation again")
    for _, fname in meta["vtk"]:
        _copy_file(donor / fname, outdir / fname)
    traj = Trajectory(outdir / "trajectory.zarr", n_frames, rods.offsets, rods.radii)
    for k in range(n):
        traj.write(k, float(src["time"][k]), np.asarray(src["positions"][k]))


def run_protocol(params, outdir, *, progress: bool = True, resume: bool = False,
                 overwrite: bool = False, thresholds=None, entangled_from=None, stages=None) -> dict:
    """Run the whole experiment and write its outputs to ``outdir``.

    ``params`` is a :class:`ProtocolParams` (checked here) or the
    :class:`~rodwarp.experiments.CheckedProtocol` that its ``validate()`` returned (the check
    is not repeated).

    Writes ``summary.json`` (every parameter, seed, versions, device, dt, steps, wall time and
    the results), ``metrics.csv`` (time series), ``trajectory.zarr`` (frames every
    ``save_every`` s), ``trajectory.pvd`` with ``vtk/`` (ParaView), ``initial.npz`` and
    ``final.npz`` (rod sets, the final one with contacts), ``metrics.png`` and
    ``snapshots.png``; checkpoints every ``checkpoint_every`` s of simulated time in
    ``checkpoints/``. With ``resume`` the run continues from the newest checkpoint and ends in
    the same final state, bit for bit on the CPU, as an uninterrupted run.

    The run owns ``outdir`` through ``rodwarp-run.json`` (:mod:`rodwarp.rodset.rundir`): a
    folder holding another run is refused unless ``overwrite`` (which removes the old outputs
    first).

    ``thresholds`` (:class:`rodwarp.experiments.Thresholds`, default the measured ones) set the
    stability verdict; summary.json records them with the rule.

    When the entangling stage ends the run writes ``entangled.npz``, the checkpoint at the
    stage boundary. ``entangled_from`` (a run folder holding one, of the same parameters but
    for the test's ``freq``, ``amplitude`` and ``duration``) starts this run's stability test
    from that state instead of packing and entangling again: its outputs of the entangling
    stage are copied, and the run ends, bit for bit on the CPU, where a run of its own
    entangling ends (docs/protocol.md, "One entangled packing, several tests"). summary.json
    records the donor under ``entangled_from``; ``wall_time_s`` is this run's own time.

    ``stages`` (a run plan, :mod:`rodwarp.experiments._plan`) replaces the paper's
    :func:`~rodwarp.experiments._plan.plan` of ``params``: one stage with ``test`` set, names
    unique.

    Returns
    -------
    dict
        The summary.
    """
    from rodwarp import _warp
    from rodwarp.experiments import _verdict as vd
    from rodwarp.experiments._checks import CheckedProtocol, check_step_count, output_bytes
    from rodwarp.experiments._packing import orientation_statistics, random_packing
    from rodwarp.experiments._recorder import Recorder, plot_metrics
    from rodwarp.rodset import load, rundir
    from rodwarp.rodset.files import write_json
    from rodwarp.rodset.trajectory import plot_snapshots
    from rodwarp.sim import State, centroid_height, rod_contacts

    checked = params if isinstance(params, CheckedProtocol) else params.validate()
    params = checked.params  # with --initial: the input's alpha and length
    from rodwarp.experiments._protocols import plugin

    proto = plugin(params.protocol)  # None: the paper's protocol, this loop's own
    thresholds = thresholds or vd.DEFAULT_THRESHOLDS
    outdir = Path(outdir)
    donor = Path(entangled_from) if entangled_from is not None and not resume else None
    # the donor is checked before the folder is taken: a refused branch leaves --out untouched
    branch = _entangled_point(params, donor, outdir) if donor is not None else None
    run = rundir.claim(outdir, "simulate", asdict(params), SIMULATE_OUTPUTS, resume=resume,
                       overwrite=overwrite, resumable=any((outdir / "checkpoints").glob("ckpt_*.npz")),
                       need_bytes=output_bytes(checked),
                       inputs=[x for x in (params.initial, donor) if x is not None])
    device = _warp.resolve_device(params.device)
    # compiled now, with a word on stderr when the cache is cold, rather than at the first
    # launch under a progress bar that would sit at t = 0 for a minute
    _warp.load_kernels(device, _warp.SIMULATION_MODULES + (("fields",) if params.fields_every > 0 else ()),
                       progress=progress)
    t_wall = time.perf_counter()
    ckdir = outdir / "checkpoints"
    ck = None
    donor_rec = None
    if resume:
        ck = _resume_point(params, ckdir)
        rods = load(outdir / "initial.npz")
        donor_rec = _read_donor_record(outdir)
    elif branch is not None:
        ck = branch
        for name in ("initial.npz", ENTANGLED):
            _copy_file(donor / name, outdir / name)
        donor_rec = _donor_record(donor, ck[1])
        write_json(outdir / ENTANGLED_FROM, donor_rec)
        rods = load(outdir / "initial.npz")
    elif params.initial:
        rods = checked.input_rods  # loaded, in metres, and checked by validate()
    elif proto is not None:
        rods = proto.packing(params, device)
    else:
        rods = random_packing(params.rods, params.length, params.diameter, np.asarray(params.box) * params.length,
                              n_vertices=params.n_vertices, seed=params.seed, device=device)
    if not resume:
        for old in ckdir.glob("ckpt_*.npz"):
            old.unlink()
        if branch is None:
            rods.save(outdir / "initial.npz")
    orient = orientation_statistics(rods)
    rule = rod_model_rule(params)
    if rule["rod_model"] == "rigid" and params.rod_model == "auto" and not _straight(rods):
        rule.update(rod_model="elastic", rule=rule["rule"] + " (the input has curved rods: elastic)")
    if rule["rod_model"] == "elastic" and not params.initial:
        # the vertices per rod the packing was made with, and why (the input's own with --initial)
        rule["resolution"] = rod_resolution(params)
    model, solver, (box_lo, box_hi) = _build(params, rods, device, rule["rod_model"])
    sim_rods = model.rods  # the simulated rods (two vertices per rod for rigid rods)
    stages = _check_plan(tuple(stages) if stages is not None else plan(params))
    protocol_dt = _default_dt(stages, model, solver)
    check_step_count(params, params.dt or protocol_dt, "--dt" if params.dt else "the default step")

    state = model.state()
    other = State(model)
    points = solver.contacts()
    control = None
    if ck is None:
        floor0 = model.control().floor_height(0.0)
        loop = LoopPosition(y0=centroid_height(model, state, 0.0 if floor0 is None else floor0),
                            stepper={"dt": None, "vmax": float(np.linalg.norm(state.velocities(), axis=1)
                                                               .max(initial=0.0))},
                            next_ck=params.checkpoint_every)
    else:
        arrays, meta = ck
        loop = LoopPosition.from_checkpoint(meta)
        if loop.mid_stage:
            stage = stages[loop.start_stage]
            control = stage.control(model, loop.stage_t0[stage.name], loop.marks)
        saved = {k[6:]: v for k, v in arrays.items() if k.startswith("state_")}
        state.load_numpy(saved)
        points.load_numpy(saved)
    n_frames = frames(stages, params.save_every)
    if branch is not None:
        _take_entangling(donor, outdir, ck[1], n_frames, sim_rods)
    rec = Recorder(outdir, model, solver, sim_rods, n_frames, checkpoint=ck,
                   done=[s.name for s in stages[:loop.start_stage]], fields_every=params.fields_every,
                   columns=proto.columns if proto is not None else None)

    # the verdict's pile reference measures the input rods (a rigid rod's two-vertex chord may
    # differ from its polyline's length in the last bits)
    longest = float(np.max(rods.rod_lengths()))
    state, control = _step_stages(params, model, solver, stages, (state, other, points), control, loop, rec, longest,
                                  progress)

    wall = time.perf_counter() - t_wall
    c = rod_contacts(model, state, points)
    final = sim_rods.with_points(state.positions(), velocities=state.velocities())
    final.contacts = c
    final.attrs.update({"time": state.time})
    final.save(outdir / "final.npz")
    rec.snapshot("end", state.positions())
    plot_snapshots(outdir / "snapshots.png", rec.snapshots, sim_rods.offsets, box=(box_lo, box_hi))
    floor = control.floor_height(state.time)
    test = next(s for s in stages if s.test)
    summary = _summary(params, model, rec.rows, loop, vd.judge_rows(rec.rows, loop.pile_ref.time, thresholds,
                                                                    stage=test.name),
                       c, centroid_height(model, state, 0.0 if floor is None else floor), rule,
                       {"device": device, "wall_time_s": wall, "resumed": bool(resume), "initial_orientation": orient,
                        "fields_wall_s": rec.fields_wall_s,
                        "entangled_from": donor_rec})
    if proto is not None:
        key, block = proto.summary(params, model, rec.rows, loop, stages, thresholds)
        summary[key] = block
    rec.write_metrics()
    write_json(outdir / "summary.json", summary)
    plot_metrics(outdir / "metrics.png", rec.rows, summary)
    rec.finish()
    run.complete()
    return summary


def _donor_record(donor: Path, meta: dict) -> dict:
    """summary.json's ``entangled_from``: the run whose entangled packing this run's test took."""
    from rodwarp.rodset import rundir

    m = rundir._read_manifest(donor) or {}
    return {"run": str(donor.resolve()), "run_id": m.get("run_id"), "time": meta["rows"][-1]["time"],
            "steps": meta["steps"], "entangle_wall_s": meta["dts"].get(ENTANGLE, {}).get("wall_s")}


def _read_donor_record(outdir: Path):
    """A resumed run's ``entangled_from``, as its first process recorded it (None if it had none)."""
    path = outdir / ENTANGLED_FROM
    return json.loads(path.read_text()) if path.exists() else None


#: where a branched run keeps its ``entangled_from`` record until summary.json is written (a
#: resumed branch reports its donor too)
ENTANGLED_FROM = "entangled_from.json"


def _step_stages(params, model, solver, stages, engine, control, loop, rec, longest: float, progress: bool):
    """Step through ``stages`` from ``loop``'s position, sampling and checkpointing on the way.

    Every step is the adaptive step (:meth:`RodSolver.adaptive_dt`, or ``params.dt``),
    shortened so that equal steps land exactly on the next sample time; a sample is taken on
    landing and a checkpoint whenever ``checkpoint_every`` of simulated time has passed.
    ``engine`` is (state, the other state it ping-pongs with, the contact points);
    ``longest`` is the longest rod (m), for the pile reference at the start of the test.

    Returns
    -------
    (State, Control)
        The final state and the last stage's control.
    """
    from rodwarp._util import progress_bar
    from rodwarp.experiments import _verdict as vd
    from rodwarp.experiments._recorder import AFTER_ENTANGLING

    parameters = asdict(params)
    state, other, points = engine
    with progress_bar(progress, seconds=True, remaining=True, note=True) as update:
        for si, stage in enumerate(stages):
            name, dur = stage.name, stage.duration
            if si < loop.start_stage:
                continue
            resuming = si == loop.start_stage and loop.mid_stage
            j0 = loop.start_j if si == loop.start_stage else 0  # samples of this stage already taken
            if not resuming:
                loop.stage_t0[name] = state.time
                if stage.strain is not None and "height0" not in loop.marks:
                    from rodwarp.experiments._lab import packing_top

                    loop.marks["height0"] = packing_top(model, state.positions())
                control = stage.control(model, state.time, loop.marks)
                loop.dts[name] = {"steps": 0, "min": None, "max": None, "mean": None, "sum": 0.0, "refused": 0}
                loop.next_ck = state.time + params.checkpoint_every
                if stage.test:
                    points.clear_wall_impulses()
                    floor = control.floor_height(state.time)
                    loop.pile_ref = vd.pile_reference(state.time, state.positions(), model.vertex_rod_np,
                                                      model.mass_np, model.n_rods, 0.0 if floor is None else floor,
                                                      longest, model.min_diameter)
            t_s0 = loop.stage_t0[name]
            t_end = t_s0 + dur
            n_samples = max(1, int(math.ceil(dur / params.save_every - 1e-9)))
            update(name, state.time - t_s0, dur)
            if si == 0 and j0 == 0 and not loop.mid_stage:
                rec.sample(name, state, points, None, control, loop, test=stage.test)
            t0 = t_mark = time.perf_counter()
            steps0 = loop.steps
            j = j0 + 1
            while j <= n_samples:
                target = t_end if j == n_samples else t_s0 + j * params.save_every
                dt = params.dt or solver.adaptive_dt(control, loop.stepper["vmax"], loop.stepper["dt"],
                                                     safety=params.step_safety,
                                                     overlap=loop.stepper.get("overlap"))
                left = target - state.time
                # reach the sample time exactly, in equal steps no longer than dt
                n_left = max(1, int(math.ceil(left / dt - 1e-6)))
                landing = n_left == 1
                dt = left / n_left
                if params.dt:
                    solver.collide(state, control, dt, points)
                    info, dt_taken, refused = solver.step(state, other, control, points, dt), dt, 0
                else:
                    info, dt_taken, refused = solver.adaptive_step(state, other, control, points, dt)
                if refused:
                    # the guard refused dt at the predictor's speeds: a shorter step, not on the sample
                    landing, dt = False, dt_taken
                state, other = other, state
                if landing:
                    state.time = target
                loop.steps += 1
                st = loop.dts[name]
                st["steps"] += 1
                st["refused"] = st.get("refused", 0) + refused  # steps the guard refused and retried shorter
                st["sum"] += dt
                st["min"] = dt if st["min"] is None else min(st["min"], dt)
                st["max"] = dt if st["max"] is None else max(st["max"], dt)
                loop.stepper["vmax"] = info.max_speed
                loop.stepper["dt"] = dt
                loop.stepper["overlap"] = info.max_overlap
                if landing:
                    rec.sample(name, state, points, info, control, loop, test=stage.test)
                    j += 1
                    rate = (loop.steps - steps0) / max(time.perf_counter() - t0, 1e-9)
                    update(name, state.time - t_s0, dur, note=f"{rate:.0f} steps/s")
                if state.time >= loop.next_ck - 1e-12 and j <= n_samples:
                    loop.next_ck += params.checkpoint_every
                    t_mark = _add_wall(st, t_mark)
                    rec.checkpoint(state, points, loop, si, j - 1, True, parameters)
            loop.dts[name]["mean"] = loop.dts[name]["sum"] / max(loop.dts[name]["steps"], 1)
            if stage.strain is not None:
                loop.marks.setdefault("strains", []).append(rec.strain_result(stage, state, points, control, params,
                                                                              loop.marks["height0"]))
            if stage.snapshot:
                rec.snapshot(AFTER_ENTANGLING if name == ENTANGLE else f"after {name}", state.positions())
            if si + 1 < len(stages):
                loop.next_ck = state.time + params.checkpoint_every
                _add_wall(loop.dts[name], t_mark)
                rec.checkpoint(state, points, loop, si + 1, 0, False, parameters,
                               keep_as=rec.outdir / ENTANGLED if stage.keep else None)
            else:
                _add_wall(loop.dts[name], t_mark)
    return state, control


def _add_wall(st: dict, since: float) -> float:
    """Add the wall time since ``since`` to a stage's record (``wall_s``: this stage's time in
    the processes that ran it, so a resumed stage counts both parts); returns now."""
    now = time.perf_counter()
    st["wall_s"] = st.get("wall_s", 0.0) + (now - since)
    return now


def _last(rows, key):
    """The last non-empty value of column ``key`` (None when there is none)."""
    for r in reversed(rows):
        if r.get(key) not in ("", None):
            return r[key]
    return None


def _summary(params, model, rows, loop, verdict, contacts, centroid_height, rule, run: dict) -> dict:
    """summary.json of a finished run: parameters, results, the verdict and provenance."""
    from rodwarp._util import versions
    from rodwarp.rodset import contacts_per_rod

    v = verdict.to_dict()
    return {
        "alpha": params.alpha, "diameter": params.diameter, "length": params.length,  # measured for --initial
        "n_rods": model.n_rods, "freq": params.freq, "amplitude": params.amplitude,
        "gravity": params.gravity, "a_over_g": params.a_over_g, "static_load": params.static_load,
        "contacts_per_rod": contacts_per_rod(model.n_rods, contacts),
        "largest_cluster_fraction": v["largest_cluster_fraction"],
        "height_kept": v["height_kept"], "persistence": v["persistence"],
        "rods_left": v["rods_left"], "stable": v["stable"], "thresholds": v["thresholds"],
        "stable_rule": v["rule"], "test_start": loop.pile_ref.to_dict(),
        "centroid_height_ratio": centroid_height / loop.y0,
        "max_penetration_over_d": max(r["max_penetration_over_d"] for r in rows),
        "rod_model": rule["rod_model"], "rod_model_rule": rule,
        "contact_law": model.contact_law.to_dict(), "rolling": model.rolling,
        "seed": params.seed, "device": run["device"], "dt": loop.dts, "steps": loop.steps,
        "wall_time_s": run["wall_time_s"], "resumed": run["resumed"], "entangled_from": run.get("entangled_from"),
        "initial_orientation": run["initial_orientation"],
        # time spent on the fields series (this process; a resumed run counts its own part)
        "fields_wall_s": run["fields_wall_s"], "cv_e_final": _last(rows, "cv_e"),
        "parameters": asdict(params), "versions": versions(),
    }
