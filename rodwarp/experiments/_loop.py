"""The stepping loop: a run plan's stages stepped on one model, sampled and checkpointed.

It knows no protocol and no stage by name: each :class:`~rodwarp.experiments._plan.Stage`
brings its walls and its motion, the motion measures what it needs when its stage begins and
records what it measured when it ends (:class:`StageEnd`), and a
:class:`~rodwarp.experiments._recorder.Recorder` takes the samples and the checkpoints. Every
step is the adaptive step (:meth:`~rodwarp.sim.RodSolver.adaptive_dt`) or the fixed ``dt``,
shortened so that equal steps land exactly on the next sample time. A checkpoint holds the
loop's position (:class:`LoopPosition`), so a resumed run is bit-identical.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path


@dataclass
class StepMemory:
    """The adaptive step's memory, checkpointed so that a resumed run picks the same steps.

    Attributes
    ----------
    dt : float or None
        The last step (s); None before the first.
    vmax : float
        The fastest vertex speed after it (m/s).
    overlap : float or None
        The largest overlap after it, in diameters; None before the first step.
    """

    dt: float | None
    vmax: float
    overlap: float | None = None

    def to_dict(self) -> dict:
        out = {"dt": self.dt, "vmax": self.vmax}
        if self.overlap is not None or self.dt is not None:
            out["overlap"] = self.overlap
        return out


@dataclass
class StageSteps:
    """One stage's steps, for summary.json's ``dt`` block.

    Attributes
    ----------
    steps, refused : int
        Steps taken, and steps the guard refused and retried shorter.
    min, max, mean, sum : float or None
        The steps' extremes, mean and total (s); ``mean`` once the stage has ended.
    wall_s : float or None
        Wall time of the stage in the processes that ran it (s; a resumed stage counts both
        parts); None until first measured.
    """

    steps: int = 0
    min: float | None = None
    max: float | None = None
    mean: float | None = None
    sum: float = 0.0
    refused: int = 0
    wall_s: float | None = None

    def add(self, dt: float, refused: int) -> None:
        """Count one step of ``dt`` (s) and the ``refused`` tries before it."""
        self.steps += 1
        self.refused += refused
        self.sum += dt
        self.min = dt if self.min is None else min(self.min, dt)
        self.max = dt if self.max is None else max(self.max, dt)

    def add_wall(self, since: float) -> float:
        """Add the wall time since ``since`` (``time.perf_counter()``); returns now."""
        now = time.perf_counter()
        self.wall_s = (self.wall_s or 0.0) + (now - since)
        return now

    def to_dict(self) -> dict:
        out = asdict(self)
        if self.wall_s is None:
            del out["wall_s"]
        return out

    @classmethod
    def from_dict(cls, d: dict) -> "StageSteps":
        return cls(**{k: d[k] for k in ("steps", "min", "max", "mean", "sum", "refused", "wall_s") if k in d})


@dataclass
class LoopPosition:
    """Where the stepping loop stands: what a checkpoint restores besides the engine state and
    the samples (those are the :class:`~rodwarp.experiments._recorder.Recorder`'s).

    Attributes
    ----------
    y0 : float
        Mass centroid height above the floor at t = 0 (m), the reference of y_c(t)/y_c(0).
    stepper : StepMemory
        The adaptive step's memory.
    next_ck : float
        Simulated time of the next checkpoint (s).
    steps : int
        Steps taken so far.
    pile_ref : PileReference or None
        The pile when the test stage started (the verdict's reference).
    stage_t0 : dict
        Start time of each stage begun (s), by stage name.
    dts : dict of StageSteps
        Each stage's steps, by stage name.
    start_stage, start_j, mid_stage
        Where the loop starts: the stage index, the samples of that stage already taken, and
        whether that stage is under way (a resumed run) or starts afresh.
    marks : dict
        What the stages' motions measured for later stages and for summary.json (JSON values,
        checkpointed; e.g. the lab's packing height when pressing began and its strains).
    """

    y0: float
    stepper: StepMemory
    next_ck: float
    steps: int = 0
    pile_ref: object = None
    stage_t0: dict = field(default_factory=dict)
    dts: dict = field(default_factory=dict)
    start_stage: int = 0
    start_j: int = 0
    mid_stage: bool = False
    marks: dict = field(default_factory=dict)

    def dts_dict(self) -> dict:
        """``dts`` as JSON (summary.json's ``dt``, a checkpoint's ``dts``)."""
        return {k: v.to_dict() for k, v in self.dts.items()}

    @classmethod
    def from_checkpoint(cls, meta: dict) -> "LoopPosition":
        from rodwarp.experiments._verdict import PileReference

        s = meta["stepper"]
        return cls(y0=meta["y0"], stepper=StepMemory(s["dt"], s["vmax"], s.get("overlap")),
                   next_ck=float(meta["next_ck"]), steps=meta["steps"],
                   pile_ref=PileReference.from_dict(meta["pile_ref"]) if meta.get("pile_ref") else None,
                   stage_t0={k: float(v) for k, v in meta["stage_t0"].items()},
                   dts={k: StageSteps.from_dict(v) for k, v in meta["dts"].items()},
                   start_stage=meta["stage"], start_j=meta["j"], mid_stage=meta["mid_stage"],
                   marks=dict(meta.get("marks", {})))


@dataclass
class StageEnd:
    """What a stage's motion may read when its stage ends (``motion.end(stage, run)``)."""

    model: object
    solver: object
    rods: object
    outdir: Path
    state: object
    points: object
    control: object
    params: object
    marks: dict


@dataclass
class Engine:
    """The engine a loop steps: the state, the one it ping-pongs with, and the contact points."""

    state: object
    other: object
    points: object


def step_stages(params, model, solver, stages, engine: Engine, control, loop: LoopPosition, rec, longest: float,
                progress: bool):
    """Step through ``stages`` from ``loop``'s position, sampling and checkpointing on the way.

    ``params`` gives the run's step options (``dt``, ``step_safety``, ``save_every``,
    ``checkpoint_every``); ``longest`` is the longest rod (m), for the pile reference at the
    start of the test stage.

    Returns
    -------
    (State, Control)
        The final state and the last stage's control.
    """
    from rodwarp._util import progress_bar

    parameters = asdict(params)
    state = engine.state
    with progress_bar(progress, seconds=True, remaining=True, note=True) as update:
        for si, stage in enumerate(stages):
            if si < loop.start_stage:
                continue
            resuming = si == loop.start_stage and loop.mid_stage
            j0 = loop.start_j if si == loop.start_stage else 0  # samples of this stage already taken
            if not resuming:
                control = _begin_stage(params, model, stage, engine, loop, longest)
            state, t_mark = _step_stage(params, solver, stage, si, engine, control, loop, rec, j0, parameters, update)
            steps = loop.dts[stage.name]
            steps.mean = steps.sum / max(steps.steps, 1)
            stage.motion.end(stage, StageEnd(model, solver, rec.rods, rec.outdir, state, engine.points, control,
                                             params, loop.marks))
            if stage.snapshot:
                rec.snapshot(stage.snapshot, state.positions())
            steps.add_wall(t_mark)
            if si + 1 < len(stages):
                loop.next_ck = state.time + params.checkpoint_every
                rec.checkpoint(state, engine.points, loop, si + 1, 0, False, parameters, keep=stage.keep)
    return state, control


def _begin_stage(params, model, stage, engine: Engine, loop: LoopPosition, longest: float):
    """Start ``stage`` afresh: its start time, its motion's measurements, its control, its step
    record and, for the test stage, the verdict's pile reference. Returns its control."""
    from rodwarp.experiments import _verdict as vd

    state = engine.state
    loop.stage_t0[stage.name] = state.time
    stage.motion.begin(model, state, loop.marks)
    control = stage.control(model, state.time, loop.marks)
    loop.dts[stage.name] = StageSteps()
    loop.next_ck = state.time + params.checkpoint_every
    if stage.test:
        engine.points.clear_wall_impulses()
        floor = control.floor_height(state.time)
        loop.pile_ref = vd.pile_reference(state.time, state.positions(), model.vertex_rod_np, model.mass_np,
                                          model.n_rods, 0.0 if floor is None else floor, longest, model.min_diameter)
    return control


def _step_stage(params, solver, stage, si: int, engine: Engine, control, loop: LoopPosition, rec, j0: int,
                parameters: dict, update):
    """Step one stage from its sample ``j0`` to its end. Returns the state reached and the
    wall-clock mark of the stage's last checkpoint."""
    t_s0 = loop.stage_t0[stage.name]
    dur = stage.duration
    every = stage.interval(params.save_every)
    n_samples = max(1, int(math.ceil(dur / every - 1e-9)))
    update(stage.name, engine.state.time - t_s0, dur)
    if si == 0 and j0 == 0 and not loop.mid_stage:
        rec.sample(stage.name, engine.state, engine.points, None, control, loop, test=stage.test)
    t0 = t_mark = time.perf_counter()
    steps0 = loop.steps
    record = loop.dts[stage.name]
    j = j0 + 1
    while j <= n_samples:
        target = t_s0 + dur if j == n_samples else t_s0 + j * every
        info, refused, dt, landing = _one_step(params, solver, engine, control, loop, target)
        loop.steps += 1
        record.add(dt, refused)
        loop.stepper = StepMemory(dt, info.max_speed, info.max_overlap)
        state = engine.state
        if landing:
            rec.sample(stage.name, state, engine.points, info, control, loop, test=stage.test)
            j += 1
            rate = (loop.steps - steps0) / max(time.perf_counter() - t0, 1e-9)
            update(stage.name, state.time - t_s0, dur, note=f"{rate:.0f} steps/s")
        if state.time >= loop.next_ck - 1e-12 and j <= n_samples:
            loop.next_ck += params.checkpoint_every
            t_mark = record.add_wall(t_mark)
            rec.checkpoint(state, engine.points, loop, si, j - 1, True, parameters)
    return engine.state, t_mark


def _one_step(params, solver, engine: Engine, control, loop: LoopPosition, target: float):
    """One step towards the sample time ``target`` (s): ``(StepInfo, tries refused before it,
    dt, landing)``, the state advanced in ``engine`` (the two states swapped)."""
    state, other, points = engine.state, engine.other, engine.points
    dt = params.dt or solver.adaptive_dt(control, loop.stepper.vmax, loop.stepper.dt, safety=params.step_safety,
                                         overlap=loop.stepper.overlap)
    left = target - state.time
    # reach the sample time exactly, in equal steps no longer than dt
    n_left = max(1, int(math.ceil(left / dt - 1e-6)))
    landing = n_left == 1
    dt = left / n_left
    if params.dt:
        solver.collide(state, control, dt, points)
        info, refused = solver.step(state, other, control, points, dt), 0
    else:
        info, dt_taken, refused = solver.adaptive_step(state, other, control, points, dt)
        if refused:
            # the guard refused dt at the predictor's speeds: a shorter step, not on the sample
            landing, dt = False, dt_taken
    engine.state, engine.other = other, state
    if landing:
        other.time = target
    return info, refused, dt, landing
