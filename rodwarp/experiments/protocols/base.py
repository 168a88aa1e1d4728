"""What a protocol plug-in provides: the hooks :func:`rodwarp.experiments.run_protocol` calls.

A protocol is one module under :mod:`rodwarp.experiments.protocols` holding one
:class:`Protocol` object, registered by one row in :data:`rodwarp.experiments.protocols.PROTOCOLS`.
It owns its options (``fields``: the :class:`~rodwarp.experiments.ProtocolParams` fields it
takes beyond the shared ones; every other protocol's are refused), their defaults
(``resolve``), its checks (``check``), its rods (``rods``, ``packing``), its scene (``walls``),
its stages (``plan``: :class:`~rodwarp.experiments._plan.Stage` objects whose motions measure
what the protocol records), its metrics.csv columns (``columns``) and its summary.json block
(``summary``). The stepping loop knows none of them by name.
"""

from __future__ import annotations


class Protocol:
    """A protocol plug-in: override the hooks the protocol needs (docs/extending.md).

    Attributes
    ----------
    name : str
        Its ``--protocol`` value.
    help : str
        What it does, for ``--protocol``'s help line.
    Params : dataclass or None
        Its own parameters (fields made with :func:`rodwarp.experiments._option.param`), part of
        :class:`~rodwarp.experiments.ProtocolParams` and of ``rodwarp simulate``'s options.
    fields : tuple of str
        The :class:`~rodwarp.experiments.ProtocolParams` fields only this protocol (or a few)
        takes; given with another protocol they are refused in one line.
    poured : bool
        The rods are poured into an open container rather than placed in a closed box: no
        ``--box`` stroke check, no density check of the random packing (the pour column is
        dilute by construction).
    branch : bool
        Its first stage may be taken from another run (``--entangled-from``).
    """

    name = ""
    help = ""
    Params = None
    fields: tuple = ()
    poured = False
    branch = False

    def resolve(self, params, explicit=None):
        """``params`` with the protocol's own defaults for the options not given."""
        return params

    def check(self, params) -> None:
        """The protocol's own checks of ``params`` (raise a one-line RodwarpError)."""

    def rods(self, params) -> int:
        """The number of rods when ``--n-rods`` is not given."""
        raise NotImplementedError

    def packing(self, params, device):
        """The initial rod set (m)."""
        raise NotImplementedError

    def walls(self, builder, params, rods):
        """Add the scene's walls to ``builder``; return the scene's box (lo, hi) in m for figures."""
        raise NotImplementedError

    def plan(self, params) -> tuple:
        """The stages, in order (exactly one with ``test=True``)."""
        raise NotImplementedError

    def pour_radius(self, params) -> float | None:
        """Radius (m) of the cylinder the rods are poured into; None: no pour."""
        return None

    def columns(self, model, x, control, t) -> dict:
        """metrics.csv's extra columns at a sample (positions ``x`` in m, time ``t`` in s)."""
        return {}

    def summary(self, params, model, rows, loop, stages, thresholds):
        """``(key, block)`` that summary.json gains, or None."""
        return None

    def notes(self, params) -> list[str]:
        """Notes printed before the run (stderr)."""
        return []
