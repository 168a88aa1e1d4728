"""The run plan: the stages a protocol run steps through, written once.

:func:`plan` turns the parameters into stages (:class:`Stage`); the checks, the stepping loop,
the recorder, the verdict and the output all iterate the plan, and no other module names a
stage. A protocol of other stages is another plan: a stage added in one place (a container
lifted away before the test, a compression) runs through the same loop, checkpoints and
outputs (docs/protocol.md, "The run plan").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rodwarp.sim import STEPS_PER_PERIOD

#: the stages of the paper's protocol, by the names metrics.csv's ``stage`` column carries
ENTANGLE = "entangle"
TEST = "stability"
#: walls a closed container has beside its floor (``Model.add_box``)
SIDE_WALLS = ("ceiling", "x-", "x+", "y-", "y+")
#: the laboratory protocol's stages (docs/experiments.md) and walls: the floor (the shaken
#: plate), the cylinder the rods are poured into, and the piston that presses them
POUR, LIFT, SHAKE, PRESS = "pour", "lift", "shake", "press"
FLOOR, TUBE, PISTON = "floor", "tube", "piston"


@dataclass(frozen=True)
class Stage:
    """One stage of a run.

    Attributes
    ----------
    name : str
        Its label in metrics.csv and summary.json; unique within a plan.
    duration : float
        Simulated time (s).
    amplitude, freq : float
        Drive of the moving walls: displacement amplitude (m) and frequency (Hz); 0 for none.
    walls_out : tuple of str
        Walls taken out for the stage (``Control.remove_walls``); the others are in place.
    test : bool
        The stability test: the verdict's pile reference is taken at its start and its samples
        are judged.
    keep : bool
        Keep the checkpoint at its end as ``entangled.npz`` (the donor of ``--entangled-from``).
    snapshot : bool
        Draw the packing at its end in snapshots.png.
    title, option : str
        How the checks name the stage and the option that sets its duration.
    moving : tuple of str or None
        The walls that follow the drive in this stage (``Control.set_moving``); None: the
        model's own ``moving`` flags.
    strain : (float, float) or None
        A piston stage: the compressive strain of the packing at its start and the one it is
        pressed to (over the first half of the stage, then held), of the packing's height
        when the first piston stage began (``marks["height0"]``).
    from_rest : bool
        The drive starts at rest at its lowest point (``Control.set_drive(from_rest=True)``).
    """

    name: str
    duration: float
    amplitude: float = 0.0
    freq: float = 0.0
    walls_out: tuple = ()
    test: bool = False
    keep: bool = False
    snapshot: bool = False
    title: str = ""
    option: str = ""
    moving: tuple | None = None
    strain: tuple | None = None
    from_rest: bool = False

    def control(self, model, t0: float, marks: dict | None = None):
        """The stage's :class:`~rodwarp.sim.Control`: its walls in place and its drive, the
        drive's phase (or ramp) starting at ``t0`` (s). ``marks`` holds what a piston stage
        needs from the run (:func:`piston_travel`)."""
        control = model.control()
        if self.walls_out:
            control.remove_walls(self.walls_out)
        if self.moving is not None:
            control.set_moving(self.moving)
        if self.strain is None:
            control.set_drive(self.amplitude, self.freq, phase_time=t0, from_rest=self.from_rest)
        elif marks is None or "height0" not in marks:
            control.set_ramp(0.0, self.duration, direction=(0.0, 0.0, -1.0), start_time=t0)  # sizing a run: at rest
        else:
            d0, d1 = (piston_travel(model, marks["height0"], e) for e in self.strain)
            ramp = 0.5 * self.duration
            control.set_ramp((d1 - d0) / ramp, ramp, direction=(0.0, 0.0, -1.0), start_time=t0, start=d0)
        return control

    def min_steps(self, per_period: float = STEPS_PER_PERIOD) -> float:
        """A lower bound on its steps: ``per_period`` steps per drive period."""
        return per_period * self.freq * self.duration


def plan(params) -> tuple[Stage, ...]:
    """The stages of the paper's protocol for ``params``
    (:class:`~rodwarp.experiments.ProtocolParams`): entangling in the closed container, unless
    skipped (``entangle_duration`` 0, or an ``initial`` rod set without ``entangle``), then the
    stability test on the floor alone; another ``protocol``: its plug-in's plan
    (:func:`lab_plan`, :func:`rodwarp.experiments._excitation.excitation_plan`)."""
    from rodwarp.experiments._protocols import plugin

    if (proto := plugin(params.protocol)) is not None:
        return proto.plan(params)
    stages = []
    if params.entangle_duration > 0 and (not params.initial or params.entangle):
        stages.append(Stage(ENTANGLE, params.entangle_duration, params.entangle_amplitude, params.entangle_freq,
                            keep=True, snapshot=True, title="entangling", option="--entangle-duration"))
    stages.append(Stage(TEST, params.duration, params.amplitude, params.freq, walls_out=SIDE_WALLS, test=True,
                        title="stability test", option="--duration"))
    return tuple(stages)


def lab_plan(params) -> tuple[Stage, ...]:
    """The laboratory protocol (docs/experiments.md): the rods poured into the cylinder, settle
    (``pour_duration``); pressed by the piston to each of ``strains`` in turn, each held until
    the end of its ``press_duration``; the cylinder (and piston) lifted away, the packing left
    to stand or spread (``lift_duration``); the plate (the floor) shaken at ``freq``,
    ``amplitude`` for ``duration``, the test. Without shaking the lift is the test. Stages of
    zero duration are left out."""
    stages = [Stage(POUR, params.pour_duration, walls_out=(PISTON,), moving=(), snapshot=True, title="pour",
                    option="--pour-duration")]
    prev = 0.0
    for e in params.strains:
        stages.append(Stage(f"{PRESS}{e:g}", params.press_duration, moving=(PISTON,), strain=(prev, float(e)),
                            snapshot=True, title=f"press to strain {e:g}", option="--press-duration"))
        prev = float(e)
    shake = params.duration > 0
    if params.lift_duration > 0:
        stages.append(Stage(LIFT, params.lift_duration, walls_out=(TUBE, PISTON), moving=(), test=not shake,
                            snapshot=True, title="container lifted", option="--lift-duration"))
    if shake:
        stages.append(Stage(SHAKE, params.duration, params.amplitude, params.freq, walls_out=(TUBE, PISTON),
                            moving=(FLOOR,), test=True, from_rest=True, title="shaking", option="--duration"))
    return tuple(stages)


def piston_travel(model, height0: float, strain: float) -> float:
    """How far the piston has come down (m) when the packing, ``height0`` tall (m, above the
    floor) when pressing began, is at compressive ``strain``."""
    top = next(w for w in model.walls if w.name == PISTON)
    return -top.offset - height0 * (1.0 - strain)  # the piston is the half-space z <= -offset


def frames(stages, save_every: float) -> int:
    """Trajectory frames of a run: the start and every sample of every stage."""
    return 1 + sum(int(math.ceil(s.duration / save_every)) + 1 for s in stages)
