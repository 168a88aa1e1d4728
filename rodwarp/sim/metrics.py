"""Packing metrics from a simulation state: contacts, contact clusters, centroid height."""

from __future__ import annotations

import numpy as np
import warp as wp
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from rodwarp.kernels import narrowphase
from rodwarp.rodset import Contacts
from rodwarp.sim.model import Model
from rodwarp.sim.state import State


def rod_contacts(model: Model, state: State, tolerance: float | None = None) -> Contacts:
    """Rod-rod contacts of ``state``: segment pairs with surface gap below ``tolerance``.

    Gaps are re-evaluated at the state's positions for the pairs the last step detected
    (its speculative margin includes every pair within the contact distance).

    Parameters
    ----------
    tolerance : float, optional
        Contact distance (m); default ``model.contact_distance`` (d / 10).

    Returns
    -------
    Contacts
        One entry per touching rod pair (the closest of its segment pairs).
    """
    tol = model.contact_distance if tolerance is None else tolerance
    n = state.contact_count
    if n == 0:
        return Contacts(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))
    dev = model.device
    gap = wp.zeros(n, dtype=wp.float64, device=dev)
    scratch = wp.zeros(1, dtype=wp.float64, device=dev)
    wp.launch(narrowphase.contact_overlap, dim=n, device=dev, inputs=[
        n, state.contact_seg, model.arrays.seg_vertex, model.arrays.vertex_rod, model.arrays.radius, state.x, gap,
        scratch])
    g = gap.numpy()
    seg = state.contact_seg.numpy()[:n]
    st = state.contact_st.numpy()[:n]
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


def contacts_per_rod(n_rods: int, c: Contacts) -> float:
    """Mean number of rod-rod contacts per rod Z = 2 K / N."""
    return 2.0 * len(c) / max(n_rods, 1)


def largest_cluster(n_rods: int, c: Contacts) -> np.ndarray:
    """Membership (N,) bool of the largest connected component of the contact graph
    (the lowest-labelled one among equal sizes, so the choice is deterministic)."""
    if n_rods == 0:
        return np.zeros(0, bool)
    if len(c) == 0:
        m = np.zeros(n_rods, bool)
        m[0] = True
        return m
    g = coo_matrix((np.ones(len(c)), (c.rod_i, c.rod_j)), shape=(n_rods, n_rods))
    _, labels = connected_components(g, directed=False)
    return labels == int(np.argmax(np.bincount(labels)))


def largest_cluster_fraction(n_rods: int, c: Contacts) -> float:
    """Rods in the largest connected component of the contact graph, over all rods (f)."""
    if n_rods == 0:
        return 0.0
    return float(np.count_nonzero(largest_cluster(n_rods, c)) / n_rods)


def centroid_height(model: Model, state: State, floor: float = 0.0) -> float:
    """Mass-weighted mean height of all vertices above the floor plane z = ``floor`` (m)
    (``Control.floor_height`` gives the floor of a scene at a time)."""
    x = state.x.numpy()
    return float(np.average(x[:, 2], weights=model.mass_np) - floor)
