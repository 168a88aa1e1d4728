"""The run plan: a protocol's stages, each composed of pieces.

A :class:`Stage` is a name and a duration, the walls taken out, the walls that move, and a
motion: :class:`Vibrate` (a sinusoidal drive, or rest at amplitude 0) or a protocol's own
(the lab's piston pressing to a strain, :class:`rodwarp.experiments.protocols.lab.PressTo`).
A motion sets the stage's :class:`~rodwarp.sim.Control` and may measure the run when its stage
begins and ends (``begin``, ``end``). :func:`rodwarp.experiments.protocols.plan` asks the protocol plug-in for its stages; the checks, the stepping loop
(:mod:`rodwarp.experiments._loop`), the recorder and the output iterate them and name none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Vibrate:
    """The moving walls vibrate sinusoidally: displacement amplitude (m) and frequency (Hz); both 0
    is rest. ``from_rest``: the drive starts at rest at its lowest point
    (``Control.set_drive(from_rest=True)``)."""

    amplitude: float = 0.0
    freq: float = 0.0
    from_rest: bool = False

    def apply(self, control, model, duration: float, t0: float, marks: dict | None) -> None:
        """Set the drive on ``control``, its phase starting at ``t0`` (s)."""
        control.set_drive(self.amplitude, self.freq, phase_time=t0, from_rest=self.from_rest)

    def begin(self, model, state, marks: dict) -> None:
        """Nothing to measure before a vibration."""

    def end(self, stage, run) -> None:
        """Nothing to record after a vibration."""


#: a stage without motion: the walls stand still
REST = Vibrate()


@dataclass(frozen=True)
class Stage:
    """One stage of a run.

    Attributes
    ----------
    name : str
        Its label in metrics.csv and summary.json; unique within a plan.
    duration : float
        Simulated time (s).
    motion : Vibrate or a protocol's motion
        What the moving walls do (:data:`REST`: nothing).
    walls_out : tuple of str
        Walls taken out for the stage (``Control.remove_walls``); the others are in place.
    moving : tuple of str or None
        The walls that follow the motion (``Control.set_moving``); None: the model's own
        ``moving`` flags.
    test : bool
        The stability test: the verdict's pile reference is taken at its start and its samples
        are judged.
    keep : bool
        Keep the checkpoint at its end as ``entangled.npz`` (the donor of ``--entangled-from``).
    snapshot : str
        The packing at the stage's end is drawn in snapshots.png under this title ("" none).
    title, option : str
        How the checks name the stage and the option that sets its duration.
    sample_every : float or None
        Its sample interval (s); None: the run's ``save_every``. The test stage samples a fixed
        number of times per drive cycle with ``--samples-per-cycle``.
    """

    name: str
    duration: float
    motion: object = REST
    walls_out: tuple = ()
    moving: tuple | None = None
    test: bool = False
    keep: bool = False
    snapshot: str = ""
    title: str = ""
    option: str = ""
    sample_every: float | None = None

    def interval(self, save_every: float) -> float:
        """Its sample interval (s): its own ``sample_every``, else the run's ``save_every``."""
        return self.sample_every or save_every

    @property
    def amplitude(self) -> float:
        """The drive's amplitude (m; 0 for a motion that is no vibration)."""
        return float(getattr(self.motion, "amplitude", 0.0))

    @property
    def freq(self) -> float:
        """The drive's frequency (Hz; 0 for a motion that is no vibration)."""
        return float(getattr(self.motion, "freq", 0.0))

    def control(self, model, t0: float, marks: dict | None = None):
        """The stage's :class:`~rodwarp.sim.Control`: its walls in place and its motion, starting
        at ``t0`` (s). ``marks`` holds what the run measured for its stages (None: sizing a run
        before it starts)."""
        control = model.control()
        if self.walls_out:
            control.remove_walls(self.walls_out)
        if self.moving is not None:
            control.set_moving(self.moving)
        self.motion.apply(control, model, self.duration, t0, marks)
        return control

    def min_steps(self, per_period: float | None = None) -> float:
        """A lower bound on its steps: ``per_period`` steps per drive period (default the
        engine's :data:`~rodwarp.sim.STEPS_PER_PERIOD`)."""
        if per_period is None:
            from rodwarp.sim import STEPS_PER_PERIOD  # the engine (and Warp) only when asked

            per_period = STEPS_PER_PERIOD
        return per_period * self.freq * self.duration


def check_plan(stages) -> tuple[Stage, ...]:
    """Refuse a plan without exactly one test stage or with a name twice (one line)."""
    from rodwarp.errors import RodwarpError

    names = [s.name for s in stages]
    if sum(s.test for s in stages) != 1:
        raise RodwarpError(f"a run plan needs exactly one test stage (Stage(test=True)); got {names}")
    if len(set(names)) != len(names):
        raise RodwarpError(f"stage names must be unique in a run plan; got {names}")
    return tuple(stages)


def frames(stages, save_every: float) -> int:
    """Trajectory frames of a run: the start and every sample of every stage."""
    return 1 + sum(int(math.ceil(s.duration / s.interval(save_every))) + 1 for s in stages)


def sampled_per_cycle(stages, samples_per_cycle: int | None) -> tuple[Stage, ...]:
    """The plan with its test stage sampled ``samples_per_cycle`` times per drive period (its
    ``sample_every`` = 1 / (samples_per_cycle f)); unchanged when None or the test has no drive."""
    import dataclasses

    if not samples_per_cycle:
        return tuple(stages)
    return tuple(dataclasses.replace(s, sample_every=1.0 / (samples_per_cycle * s.freq)) if s.test and s.freq > 0
                 else s for s in stages)
