"""The protocols ``rodwarp simulate --protocol`` runs, and their plug-ins.

``paper`` is the loop's own protocol (docs/protocol.md). Every other protocol is one plug-in
object that owns its defaults (``resolve``), stages (``plan``), scene (``packing``, ``walls``),
checks (``check``), metrics columns (``columns``), rod count (``rods``) and summary.json block
(``summary``); :func:`rodwarp.experiments.run_protocol` calls these hooks and names no stage of
its own. A new protocol is one module and one line here.
"""

from __future__ import annotations

#: the protocols, the paper's first
PROTOCOLS = ("paper", "lab", "excitation")


def plugin(name: str):
    """The plug-in of protocol ``name``; None for ``paper`` (or an unknown name, which the
    checks refuse)."""
    if name == "lab":
        from rodwarp.experiments._lab import LAB

        return LAB
    if name == "excitation":
        from rodwarp.experiments._excitation import EXCITATION

        return EXCITATION
    return None
