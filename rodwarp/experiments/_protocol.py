"""A protocol run: the plan of its protocol's stages stepped by one loop, and its outputs.

:func:`run_protocol` builds the scene its protocol plug-in describes
(:mod:`rodwarp.experiments.protocols`: packing, walls, stages, columns, summary block), steps
the stages on one model with :func:`rodwarp.experiments._loop.step_stages`, which takes
adaptive steps that land exactly on the sample times while a
:class:`~rodwarp.experiments._recorder.Recorder` takes the samples and the checkpoints, and
writes the outputs. A checkpoint holds the loop's own position, so a resumed run is
bit-identical. The stability verdict (:mod:`rodwarp.experiments._verdict`, docs/verdict.md)
judges the samples of the plan's test stage; the paper's protocol is docs/protocol.md, the
others docs/experiments.md.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from rodwarp.errors import RodwarpError
from rodwarp.experiments._loop import Engine, LoopPosition, StepMemory, step_stages
from rodwarp.experiments._params import ProtocolParams, _straight, rod_model_rule, rod_resolution
from rodwarp.experiments._plan import check_plan, frames
from rodwarp.experiments.protocols import plan
from rodwarp.experiments._recorder import ENTANGLED
from rodwarp.rodset.commands import SIMULATE_OUTPUTS


def _build(params: ProtocolParams, rods, device, rod_model: str, proto=None):
    """Model and solver of the run, the scene's walls from its protocol (``proto``, default
    ``params.protocol``'s; deterministic given the parameters and rods); also the scene's box
    (lo, hi) in m."""
    from rodwarp.experiments.protocols import protocol
    from rodwarp.sim import Material, ModelBuilder, RodSolver

    proto = proto or protocol(params.protocol)
    g_eff = params.effective_gravity
    builder = ModelBuilder(rods, Material(params.young, params.density), gravity=(0.0, 0.0, -g_eff), mu=params.mu,
                           rod_model=rod_model, rolling=params.spin, contact_law=params.contact_law_object(),
                           device=device)
    box = proto.walls(builder, params, rods)
    model = builder.finalize()
    return model, RodSolver(model, iterations=params.iterations, steps_per_period=params.steps_per_period), box


def _default_dt(stages, model, solver) -> float:
    """The worst-case step of the run (s): the smallest of the solver's default steps under the
    drives of its stages, at the scene's characteristic speed. It sizes the run before it
    starts (:func:`~rodwarp.experiments._checks.check_step_count` refuses a run of too many
    steps); the run itself takes adaptive steps (:meth:`RodSolver.adaptive_dt`)."""
    return min(solver.default_dt(stage.control(model, 0.0)) for stage in stages)


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


#: the stability test's own parameters: a run may take its entangled packing from a run that
#: differs from it in these alone (and in the device)
TEST_FIELDS = ("freq", "amplitude", "duration", "cycles", "samples_per_cycle")


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
    # checkpoints from before the resolution rule ran every drive at 40 steps a period or more and
    # every rod at 10 vertices unless given: such a checkpoint compares by what it ran with, a run
    # of now by the resolution rule's count
    if out.get("steps_per_period") is None:
        out["steps_per_period"] = 40.0
    if out.get("vertices") is None:
        known = ProtocolParams.__dataclass_fields__
        out["vertices"] = ProtocolParams(**{k: tuple(v) if isinstance(v, list) else v for k, v in out.items()
                                            if k in known}).n_vertices
    return out


def check_branch_protocol(params: ProtocolParams) -> None:
    """Refuse ``--entangled-from`` for a protocol without an entangling stage (one line)."""
    from rodwarp.experiments.protocols import protocol

    if not protocol(params.protocol).branch:
        raise RodwarpError(f"--entangled-from applies only with --protocol paper (it starts the stability test "
                           f"from another run's entangled packing); --protocol {params.protocol} pours its packing "
                           f"and has no entangling stage: drop --entangled-from")


def _entangled_point(params: ProtocolParams, donor: Path, outdir: Path):
    """``(arrays, meta)`` of ``donor``'s end-of-entangling checkpoint, refused (one line) when
    it is missing, unreadable, or of another packing or entangling than ``params``."""
    from rodwarp.rodset.trajectory import read_checkpoint_file

    check_branch_protocol(params)
    if not plan(params)[0].keep:
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

    ``stages`` (a run plan, :mod:`rodwarp.experiments._plan`) replaces the protocol's own
    plan of ``params``: one stage with ``test`` set, names unique.

    Returns
    -------
    dict
        The summary.
    """
    from rodwarp import _warp
    from rodwarp.experiments import _verdict as vd
    from rodwarp.experiments._checks import CheckedProtocol, check_step_count, output_bytes
    from rodwarp.experiments._packing import orientation_statistics
    from rodwarp.experiments._recorder import Recorder
    from rodwarp.experiments.protocols import protocol
    from rodwarp.rodset import rundir

    checked = params if isinstance(params, CheckedProtocol) else params.validate()
    params = checked.params  # with --initial: the input's alpha and length
    proto = protocol(params.protocol)
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
    rods, ck, donor_rec = _start_rods(params, checked, proto, outdir, device, resume, branch, donor)
    orient = orientation_statistics(rods)
    rule = _rod_model(params, rods)
    model, solver, box = _build(params, rods, device, rule["rod_model"], proto)
    sim_rods = model.rods  # the simulated rods (two vertices per rod for rigid rods)
    stages = check_plan(tuple(stages) if stages is not None else plan(params))
    protocol_dt = _default_dt(stages, model, solver)
    check_step_count(params, params.dt or protocol_dt, "--dt" if params.dt else "the default step")

    engine, control, loop = _start_loop(params, model, solver, stages, ck)
    n_frames = frames(stages, params.save_every)
    if branch is not None:
        _take_entangling(donor, outdir, ck[1], n_frames, sim_rods)
    rec = Recorder(outdir, model, solver, sim_rods, n_frames, checkpoint=ck,
                   done=stages[:loop.start_stage], fields_every=params.fields_every, columns=proto.columns,
                   kept_snapshot=next((s.snapshot for s in stages if s.keep), ""))

    # the verdict's pile reference measures the input rods (a rigid rod's two-vertex chord may
    # differ from its polyline's length in the last bits)
    longest = float(np.max(rods.rod_lengths()))
    state, control = step_stages(params, model, solver, stages, engine, control, loop, rec, longest, progress)

    run_info = {"device": device, "wall_time_s": time.perf_counter() - t_wall, "resumed": bool(resume),
                "initial_orientation": orient, "fields_wall_s": rec.fields_wall_s, "entangled_from": donor_rec}
    summary = _write_outputs(params, proto, model, stages, state, engine.points, control, loop, rec, rule, box,
                             thresholds, run_info)
    run.complete()
    return summary


def _start_rods(params, checked, proto, outdir: Path, device, resume: bool, branch, donor):
    """The run's rods and where it starts: ``(rods, checkpoint or None, donor record or None)``.
    A resumed run reloads its own; a branched run copies the donor's initial rods and kept
    checkpoint; else the input rods or the protocol's packing, saved as ``initial.npz``."""
    from rodwarp.rodset import load
    from rodwarp.rodset.files import write_json

    ckdir = outdir / "checkpoints"
    ck, donor_rec = None, None
    if resume:
        ck = _resume_point(params, ckdir)
        rods = load(outdir / "initial.npz")
        donor_rec = _read_donor_record(outdir)
    elif branch is not None:
        ck = branch
        for name in ("initial.npz", ENTANGLED):
            _copy_file(donor / name, outdir / name)
        donor_rec = _donor_record(donor, ck[1], plan(params)[0].name)
        write_json(outdir / ENTANGLED_FROM, donor_rec)
        rods = load(outdir / "initial.npz")
    elif params.initial:
        rods = checked.input_rods  # loaded, in metres, and checked by validate()
    else:
        rods = proto.packing(params, device)
    if not resume:
        for old in ckdir.glob("ckpt_*.npz"):
            old.unlink()
        if branch is None:
            rods.save(outdir / "initial.npz")
    return rods, ck, donor_rec


def _rod_model(params, rods) -> dict:
    """The rod model rule's choice for these rods (curved input rods are elastic), with the
    resolution rule's reasons for a packing of elastic rods."""
    rule = rod_model_rule(params)
    if rule["rod_model"] == "rigid" and params.rod_model == "auto" and not _straight(rods):
        rule.update(rod_model="elastic", rule=rule["rule"] + " (the input has curved rods: elastic)")
    if rule["rod_model"] == "elastic" and not params.initial:
        # the vertices per rod the packing was made with, and why (the input's own with --initial)
        rule["resolution"] = rod_resolution(params)
    return rule


def _start_loop(params, model, solver, stages, ck):
    """The engine, the control of a stage under way (None otherwise) and the loop's position:
    afresh, or restored from checkpoint ``ck``."""
    from rodwarp.sim import State, centroid_height

    state, other, points = model.state(), State(model), solver.contacts()
    control = None
    if ck is None:
        floor0 = model.control().floor_height(0.0)
        loop = LoopPosition(y0=centroid_height(model, state, 0.0 if floor0 is None else floor0),
                            stepper=StepMemory(None, float(np.linalg.norm(state.velocities(), axis=1)
                                                           .max(initial=0.0))),
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
    return Engine(state, other, points), control, loop


def _write_outputs(params, proto, model, stages, state, points, control, loop, rec, rule, box, thresholds,
                   run_info: dict) -> dict:
    """The finished run's outputs: final.npz, snapshots.png, metrics.csv, summary.json (with the
    verdict on the test stage and the protocol's block) and metrics.png. Returns the summary."""
    from rodwarp.experiments import _verdict as vd
    from rodwarp.experiments._recorder import plot_metrics
    from rodwarp.rodset.files import write_json
    from rodwarp.rodset.trajectory import plot_snapshots
    from rodwarp.sim import centroid_height, rod_contacts

    outdir, sim_rods = rec.outdir, model.rods
    c = rod_contacts(model, state, points)
    final = sim_rods.with_points(state.positions(), velocities=state.velocities())
    final.contacts = c
    final.attrs.update({"time": state.time})
    final.save(outdir / "final.npz")
    rec.snapshot("end", state.positions())
    plot_snapshots(outdir / "snapshots.png", rec.snapshots, sim_rods.offsets, box=box)
    floor = control.floor_height(state.time)
    test = next(s for s in stages if s.test)
    verdict = vd.judge_rows(rec.rows, loop.pile_ref.time, thresholds, stage=test.name)
    summary = _summary(params, model, rec.rows, loop, verdict, c,
                       centroid_height(model, state, 0.0 if floor is None else floor), rule, run_info)
    per_cycle = 1.0 / (test.freq * test.interval(params.save_every)) if test.freq > 0 else 0.0
    summary["landed"] = vd.landed_rows(rec.rows, loop.pile_ref.time, test.freq, per_cycle, thresholds,
                                       stage=test.name)
    if (block := proto.summary(params, model, rec.rows, loop, stages, thresholds)) is not None:
        summary[block[0]] = block[1]
    rec.write_metrics()
    write_json(outdir / "summary.json", summary)
    plot_metrics(outdir / "metrics.png", rec.rows, summary)
    rec.finish()
    return summary


def _donor_record(donor: Path, meta: dict, kept: str) -> dict:
    """summary.json's ``entangled_from``: the run whose entangled packing this run's test took."""
    from rodwarp.rodset import rundir

    m = rundir._read_manifest(donor) or {}
    return {"run": str(donor.resolve()), "run_id": m.get("run_id"), "time": meta["rows"][-1]["time"],
            "steps": meta["steps"], "entangle_wall_s": meta["dts"].get(kept, {}).get("wall_s")}


def _read_donor_record(outdir: Path):
    """A resumed run's ``entangled_from``, as its first process recorded it (None if it had none)."""
    path = outdir / ENTANGLED_FROM
    return json.loads(path.read_text()) if path.exists() else None


#: where a branched run keeps its ``entangled_from`` record until summary.json is written (a
#: resumed branch reports its donor too)
ENTANGLED_FROM = "entangled_from.json"


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
        "seed": params.seed, "device": run["device"], "dt": loop.dts_dict(), "steps": loop.steps,
        "wall_time_s": run["wall_time_s"], "resumed": run["resumed"], "entangled_from": run.get("entangled_from"),
        "initial_orientation": run["initial_orientation"],
        # time spent on the fields series (this process; a resumed run counts its own part)
        "fields_wall_s": run["fields_wall_s"], "cv_e_final": _last(rows, "cv_e"),
        "parameters": asdict(params), "versions": versions(),
    }
