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

from rodwarp.sim._bounds import STEPS_PER_PERIOD

#: the stages of the paper's protocol, by the names metrics.csv's ``stage`` column carries
ENTANGLE = "entangle"
TEST = "stability"
#: walls a closed container has beside its floor (``Model.add_box``)
SIDE_WALLS = ("ceiling", "x-", "x+", "y-", "y+")


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

    def control(self, model, t0: float):
        """The stage's :class:`~rodwarp.sim.Control`: its walls in place and its drive, the
        drive's phase starting at ``t0`` (s)."""
        control = model.control()
        if self.walls_out:
            control.remove_walls(self.walls_out)
        control.set_drive(self.amplitude, self.freq, phase_time=t0)
        return control

    def min_steps(self) -> float:
        """A lower bound on its steps: :data:`STEPS_PER_PERIOD` per drive period."""
        return STEPS_PER_PERIOD * self.freq * self.duration


def plan(params) -> tuple[Stage, ...]:
    """The stages of the paper's protocol for ``params``
    (:class:`~rodwarp.experiments.ProtocolParams`): entangling in the closed container, unless
    skipped (``entangle_duration`` 0, or an ``initial`` rod set without ``entangle``), then the
    stability test on the floor alone."""
    stages = []
    if params.entangle_duration > 0 and (not params.initial or params.entangle):
        stages.append(Stage(ENTANGLE, params.entangle_duration, params.entangle_amplitude, params.entangle_freq,
                            keep=True, snapshot=True, title="entangling", option="--entangle-duration"))
    stages.append(Stage(TEST, params.duration, params.amplitude, params.freq, walls_out=SIDE_WALLS, test=True,
                        title="stability test", option="--duration"))
    return tuple(stages)


def frames(stages, save_every: float) -> int:
    """Trajectory frames of a run: the start and every sample of every stage."""
    return 1 + sum(int(math.ceil(s.duration / save_every)) + 1 for s in stages)
