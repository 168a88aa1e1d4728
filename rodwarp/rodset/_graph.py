"""The contact graph of a packing: rods are nodes, contacts of the packing are edges.

Plain NumPy and SciPy on :class:`~rodwarp.rodset.Contacts` (touching rod pairs), so a
simulation (:func:`rodwarp.sim.rod_contacts`), a segmentation and an analysis measure their
packings alike: contacts per rod Z and the largest contact cluster f (the seed paper's
Fig. 4H measure; docs/verdict.md).
"""

from __future__ import annotations

import numpy as np

from rodwarp.rodset._rodset import Contacts

__all__ = ["contacts_per_rod", "largest_cluster", "largest_cluster_fraction"]


def contacts_per_rod(n_rods: int, c: Contacts) -> float:
    """Mean number of rod-rod contacts per rod Z = 2 K / N."""
    return 2.0 * len(c) / max(n_rods, 1)


def largest_cluster(n_rods: int, c: Contacts) -> np.ndarray:
    """Membership (N,) bool of the largest connected component of the contact graph
    (the lowest-labelled one among equal sizes, so the choice is deterministic)."""
    # scipy loads here, not with rodwarp.rodset (`rodwarp --help` stays fast)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

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
