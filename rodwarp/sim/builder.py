"""Building a scene: :class:`ModelBuilder` collects rods, material, options and walls, and
:meth:`ModelBuilder.finalize` gives the :class:`~rodwarp.sim.model.Model`, which does not change.

As in Newton (``ModelBuilder`` -> ``finalize()`` -> ``Model``): everything a run keeps fixed is
decided before any device array exists, so states, solvers and controls made from one model all
see the same walls and sizes.

>>> builder = ModelBuilder(rods, rod_model="rigid")          # doctest: +SKIP
>>> builder.add_box([0, 0, 0], [1, 1, 2.5])                  # doctest: +SKIP
>>> model = builder.finalize()                               # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses

import numpy as np

from rodwarp.errors import RodwarpError
from rodwarp.rodset import RodSet
from rodwarp.arguments import instance
from rodwarp.sim._limits import check_model_options, check_rods, friction
from rodwarp.sim.model import STEEL, Material, Model, checked_box
from rodwarp.sim.walls import Plane, _Wall

#: the walls of an axis-aligned container (z up), as (normal, which corner, which axis)
BOX_WALLS = {"floor": ((0, 0, 1), 0, 2), "ceiling": ((0, 0, -1), 1, 2), "x-": ((1, 0, 0), 0, 0),
             "x+": ((-1, 0, 0), 1, 0), "y-": ((0, 1, 0), 0, 1), "y+": ((0, -1, 0), 1, 1)}


class ModelBuilder:
    """The makings of a :class:`~rodwarp.sim.model.Model`.

    Parameters
    ----------
    rods : RodSet
        Rods in metres (converted from mm or um at :meth:`finalize`); radii in [1 nm, 1000 km],
        coordinates within 1000 km of the origin.
    material : Material
        Elastic material of every rod (steel by default).
    **options
        The keyword parameters of :class:`~rodwarp.sim.model.Model` (gravity, mu, damping,
        pinned, contact_distance, rod_contacts, extensible, rod_model, rolling, contact_law,
        device), with the ranges stated there.

    Raises
    ------
    TypeError
        ``rods`` not a RodSet, ``material`` not a Material, an unknown option or one of the
        wrong kind.
    RodwarpError
        An option out of its range (named, with its range and unit): checked here, not at
        :meth:`finalize`.
    """

    def __init__(self, rods: RodSet, material: Material = STEEL, **options):
        check_rods(rods)
        instance("material", material, Material, "a Material (Material(young=..., density=...))")
        check_model_options(options)
        self.rods = rods
        self.material = material
        self.options = dict(options)
        self.walls: list = []  # rodwarp.sim.walls kinds, in the order the device sees them
        self.box: np.ndarray | None = None

    def add_wall(self, wall):
        """Add a wall of any kind (:mod:`rodwarp.sim.walls`: ``Plane.make(...)``,
        ``Cylinder.make(...)``); a wall without a friction coefficient takes the model's.
        Returns the wall.

        Raises
        ------
        RodwarpError
            A second wall of the same name, or a negative friction coefficient.
        """
        instance("wall", wall, _Wall, "a wall (Plane.make(...) or Cylinder.make(...))")
        if any(w.name == wall.name for w in self.walls):
            raise RodwarpError(f"the model already has a wall named '{wall.name}'; give another name")
        if wall.mu is not None:
            friction(f"mu of wall '{wall.name}'", wall.mu)
        self.walls.append(wall)
        return wall

    def add_plane(self, normal, offset: float, *, mu: float | None = None, moving: bool = False,
                  name: str = "plane") -> Plane:
        """Add a half-space wall {x : n . x >= offset} (``offset`` in m, within 1e6 m; ``mu`` in
        [0, 10]); returns the :class:`Plane`."""
        return self.add_wall(Plane.make(normal, offset, mu=mu, moving=moving, name=name))

    def add_box(self, lower, upper, *, walls=("floor", "x-", "x+", "y-", "y+"), mu: float | None = None,
                moving: bool = False) -> None:
        """Add the walls of an axis-aligned container (z up).

        Parameters
        ----------
        lower, upper : (3,) float
            Container corners (m), within 1e6 m of the origin, ``upper`` above ``lower`` on
            every axis.
        walls : sequence of str
            Which of ``floor``, ``ceiling``, ``x-``, ``x+``, ``y-``, ``y+`` to add. Walls a run
            removes later (the stability test keeps only the floor) are switched off in its
            :class:`~rodwarp.sim.control.Control`, not removed here.
        mu : float, optional
            Friction coefficient of these walls, in [0, 10] (default the model's).
        moving : bool
            Whether these walls follow the control's drive.
        """
        corners = checked_box((lower, upper), names=("lower", "upper"))
        if isinstance(walls, str):
            walls = (walls,)
        for w in walls:
            if w not in BOX_WALLS:
                raise RodwarpError(f"unknown wall '{w}'; use floor, ceiling, x-, x+, y-, y+")
            n, corner, axis = BOX_WALLS[w]
            self.add_plane(n, float(np.dot(n, np.eye(3)[axis])) * corners[corner, axis], mu=mu, moving=moving, name=w)
        self.box = corners

    def finalize(self) -> Model:
        """The :class:`~rodwarp.sim.model.Model` of this scene, allocated on its device (the
        builder may be changed and finalized again: each call gives a new model)."""
        walls = [dataclasses.replace(w) for w in self.walls]  # the model's own copies
        return Model(self.rods, self.material, walls=walls, box=self.box, **self.options)

