"""What a simulation state measures: the contacts of the packing and the centroid height.

The *contacts of the packing* (:func:`packing_contacts`) are touching rod pairs, one per pair: the
surface gap of the pair's closest segments below the contact distance (d / 10 by default,
docs/protocol.md).  They are not the solver's *contact points* (``StepInfo.n_contacts``: every
segment pair a step solves, speculative ones included) nor its *contact candidates* (the
broadphase's pair list, :class:`~rodwarp.sim.contacts.ContactPipeline`).  The contact graph's
measures (contacts per rod, the largest cluster) need no engine and live in
:mod:`rodwarp.rodset`.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from rodwarp.kernels import narrowphase
from rodwarp.rodset import Contacts
from rodwarp.arguments import optional_real, real
from rodwarp.sim._limits import MAX_LENGTH_M
from rodwarp.sim.model import Model
from rodwarp.sim.state import State


def packing_contacts(model: Model, state: State, points, tolerance: float | None = None) -> Contacts:
    """The contacts of the packing in ``state``: rod pairs whose surface gap is below ``tolerance``.

    Gaps are re-evaluated at the state's positions for the pairs the last step detected
    (its speculative margin includes every pair within the contact distance).

    Parameters
    ----------
    state : State
        The state the last step wrote.
    points : ContactPoints
        The contact points of that step (``points.last``; :meth:`RodSolver.collide`).
    tolerance : float, optional
        Contact distance (m, within 1e6 m; negative counts only overlaps deeper than it);
        default ``model.contact_distance`` (d / 10).

    Returns
    -------
    Contacts
        One entry per touching rod pair (the closest of its segment pairs).
    """
    tol = optional_real("tolerance", tolerance, ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, unit="m")
    tol = model.contact_distance if tol is None else tol
    last = points.last
    n = last.count
    if n == 0:
        return Contacts(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))
    dev = model.device
    gap = wp.zeros(n, dtype=wp.float64, device=dev)
    scratch = wp.zeros(1, dtype=wp.float64, device=dev)
    wp.launch(narrowphase.contact_overlap, dim=n, device=dev, inputs=[
        n, last.seg, model.arrays.seg_vertex, model.arrays.vertex_rod, model.arrays.radius, state.x, gap,
        scratch])
    g = gap.numpy()
    seg = last.seg.numpy()[:n]
    st = last.st.numpy()[:n]
    x = state.x.numpy()
    va = model.seg_vertex_np[seg[:, 0]]
    vb = model.seg_vertex_np[seg[:, 1]]
    ra = model.vertex_rod_np[va]
    rb = model.vertex_rod_np[vb]
    keep = (g < tol) & (ra != rb)
    pa = x[va] + st[:, :1] * (x[va + 1] - x[va])
    pb = x[vb] + st[:, 1:] * (x[vb + 1] - x[vb])
    pts = 0.5 * (pa + pb)
    lo = np.minimum(ra, rb)[keep]
    hi = np.maximum(ra, rb)[keep]
    g, pts = g[keep], pts[keep]
    if len(lo) == 0:
        return Contacts(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))
    order = np.lexsort((g, hi, lo))
    lo, hi, g, pts = lo[order], hi[order], g[order], pts[order]
    first = np.ones(len(lo), bool)
    first[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
    return Contacts(lo[first].astype(np.int64), hi[first].astype(np.int64), pts[first], g[first])


#: the name :func:`packing_contacts` had first (``Model``'s ``rod_contacts`` is the switch of rod-rod contact points)
rod_contacts = packing_contacts


def centroid_height(model: Model, state: State, floor: float = 0.0) -> float:
    """Mass-weighted mean height of all vertices above the floor plane z = ``floor`` (m)
    (``Control.floor_height`` gives the floor of a scene at a time; within 1e6 m)."""
    floor = real("floor", floor, ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, unit="m")
    x = state.x.numpy()
    return float(np.average(x[:, 2], weights=model.mass_np) - floor)
