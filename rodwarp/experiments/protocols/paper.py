"""The seed paper's numerical protocol (docs/protocol.md; the paper's "Numerical simulations of
rod packings"): N = round(5.4 alpha) straight rods placed at random in a closed 1 x 1 x 2.5 l
box, entangled by vibrating the closed container (10 Hz, 0.05 m, 5 s), then the stability
test: side walls and lid removed, the floor vibrated at ``freq``, ``amplitude`` for
``duration``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from rodwarp.experiments._option import param
from rodwarp.experiments._plan import Stage, Vibrate
from rodwarp.experiments.protocols.base import Protocol
from rodwarp.validation import Range

#: the stages, by the names metrics.csv's ``stage`` column carries
ENTANGLE = "entangle"
TEST = "stability"
#: walls a closed container has beside its floor (``ModelBuilder.add_box``): out for the test
SIDE_WALLS = ("ceiling", "x-", "x+", "y-", "y+")
#: the entangled packing's title in snapshots.png
AFTER_ENTANGLING = "after entangling"


@dataclass(frozen=True)
class PaperParams:
    """The paper protocol's own parameters: the closed box, the entangling drive, and an input
    rod set instead of the random packing."""

    entangle_duration: float = param(5.0, "Entangling duration (s); 0 skips entangling.", "edur",
          range=Range(ge=0, le=1e5, unit="s", hint="0 skips entangling"))
    entangle_freq: float = param(10.0, "Entangling vibration frequency (Hz).", "efreq",
          range=Range(ge=0, le=1000, unit="Hz", hint="the paper entangles at 10 Hz"))
    entangle_amplitude: float = param(0.05, "Entangling vibration amplitude (m).", "eamp",
          range=Range(ge=0, le=100, unit="m", hint="the stroke is also checked against the box"))
    box: tuple = param((1.0, 1.0, 2.5), "Container size in rod lengths, 'X,Y,Z'.",
          range=Range(gt=0, le=1000, each=True, hint="the box is 'X,Y,Z' in rod lengths"))
    initial: str | None = param(None, "Start from this rod set (npz, zarr or CSV) instead of a random packing.")
    # a CSV does not record its unit: without this it is read as metres (the simulation runs in SI)
    units: str | None = param(None, "Length unit of a CSV --initial rod set: m (the default), mm or um; "
                                     "converted to metres. An npz/zarr records its own.")
    initial_diameter: float | None = param(None, "Rod diameter (in --units) for a CSV --initial rod set without a "
                                                  "radius column.", "d",
          range=Range(gt=0, le=1e6, hint="in --units of the CSV"), flag="--diameter")
    entangle: bool = param(False, "With --initial: run the entangling stage too.")


class PaperProtocol(Protocol):
    """The paper's protocol: random packing in a box, entangling, the vibration test."""

    name = "paper"
    help = "random packing in a box, entangling, the vibration test; docs/protocol.md"
    Params = PaperParams
    fields = tuple(f.name for f in fields(PaperParams))
    branch = True

    def rods(self, params) -> int:
        from rodwarp.experiments._fields import RODS_PER_ALPHA

        return int(round(RODS_PER_ALPHA * params.alpha))

    def packing(self, params, device):
        from rodwarp.experiments._packing import random_packing

        return random_packing(params.rods, params.length, params.diameter, np.asarray(params.box) * params.length,
                              n_vertices=params.n_vertices, seed=params.seed, device=device)

    def walls(self, builder, params, rods):
        """The closed box, moving with the drive: the input's own container widened to its rods
        (rods lying on, or sunk into, its floor get the floor under their lowest point), or for
        an input without one, the floor under its lowest point and walls around it; the lid
        half a rod length above."""
        bb = rods.bounding_box()
        if rods.box is not None:
            lo = np.minimum(np.asarray(rods.box[0], float), bb[0])
            hi = np.maximum(np.asarray(rods.box[1], float), bb[1])
        else:
            lo, hi = bb[0], bb[1]
        builder.add_box(lo, hi + np.array([0, 0, 0.5 * params.length]), walls=("floor", *SIDE_WALLS), moving=True)
        return lo, hi

    def plan(self, params) -> tuple[Stage, ...]:
        """Entangling in the closed container, unless skipped (``entangle_duration`` 0, or an
        ``initial`` rod set without ``entangle``), then the stability test on the floor alone."""
        stages = []
        if params.entangle_duration > 0 and (not params.initial or params.entangle):
            stages.append(Stage(ENTANGLE, params.entangle_duration, Vibrate(params.entangle_amplitude,
                                                                            params.entangle_freq),
                                keep=True, snapshot=AFTER_ENTANGLING, title="entangling", option="--entangle-duration"))
        stages.append(Stage(TEST, params.duration, Vibrate(params.amplitude, params.freq), walls_out=SIDE_WALLS,
                            test=True, title="stability test", option="--duration"))
        return tuple(stages)


PAPER = PaperProtocol()
