"""The protocols ``rodwarp simulate --protocol`` runs: one module and one plug-in object each
(:class:`~rodwarp.experiments.protocols.base.Protocol`), registered in :data:`PROTOCOLS`, the
one table ``--protocol``, its checks and its help read.

=============  ===============================================================================
``paper``      the seed paper's numerical protocol (docs/protocol.md)
``lab``        rods poured into a cylinder, pressed by a piston, the cylinder lifted away, the
               plate shaken (docs/experiments.md)
``excitation`` the paper's excitation experiment, Fig. 1C-F (docs/experiments.md)
=============  ===============================================================================

A new protocol is one module here and one row in :data:`PROTOCOLS` (docs/extending.md).
"""

from __future__ import annotations

from rodwarp.errors import RodwarpError
from rodwarp.experiments.protocols.base import Protocol
from rodwarp.experiments.protocols.excitation import EXCITATION
from rodwarp.experiments.protocols.lab import LAB
from rodwarp.experiments.protocols.paper import PAPER

#: every protocol by its ``--protocol`` name, the paper's first (the default)
PROTOCOLS: dict[str, Protocol] = {p.name: p for p in (PAPER, LAB, EXCITATION)}


def register_protocol(proto: Protocol) -> Protocol:
    """Add a protocol plug-in defined outside this package (a user's own experiment) to
    :data:`PROTOCOLS`; returns it. Its parameters must be :class:`~rodwarp.experiments.
    ProtocolParams` fields already (``Params`` None): a protocol with options of its own is a
    module here and a row in the table above, which puts its fields on the command line."""
    from dataclasses import fields

    if not isinstance(proto, Protocol) or not proto.name:
        raise RodwarpError("register_protocol takes a Protocol object with a name")
    if proto.name in PROTOCOLS and PROTOCOLS[proto.name] is not proto:
        raise RodwarpError(f"protocol {proto.name!r} is registered already")
    if proto.Params is not None:
        raise RodwarpError(f"protocol {proto.name!r} has parameters of its own ({proto.Params.__name__}): add its "
                           "module to rodwarp.experiments.protocols.PROTOCOLS instead")
    from rodwarp.experiments._fields import ExperimentParams, RunParams

    known = {f.name for group in (ExperimentParams, RunParams, *(p.Params for p in PROTOCOLS.values() if p.Params))
             for f in fields(group)}
    if unknown := sorted(set(proto.fields) - known):
        raise RodwarpError(f"protocol {proto.name!r} claims fields ProtocolParams lacks: {', '.join(unknown)}")
    PROTOCOLS[proto.name] = proto
    return proto


def plan(params) -> tuple:
    """The stages of ``params.protocol`` for ``params``
    (:class:`~rodwarp.experiments.ProtocolParams`), from its plug-in; the test stage sampled
    ``samples_per_cycle`` times per drive period when that is set."""
    from rodwarp.experiments._plan import sampled_per_cycle

    return sampled_per_cycle(protocol(params.protocol).plan(params), getattr(params, "samples_per_cycle", None))


def protocol(name: str) -> Protocol:
    """The plug-in of protocol ``name`` (a one-line RodwarpError for an unknown name)."""
    try:
        return PROTOCOLS[name]
    except KeyError:
        raise RodwarpError(f"--protocol must be one of {', '.join(PROTOCOLS)}, got '{name}'") from None


__all__ = ["PROTOCOLS", "Protocol", "plan", "protocol", "register_protocol", "PAPER", "LAB", "EXCITATION"]
