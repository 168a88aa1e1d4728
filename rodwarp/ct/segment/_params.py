"""The knobs of CT segmentation and what it returns: :class:`SegmentParams`, :class:`SegmentResult`.

Lengths are in (working) voxels; see :func:`rodwarp.ct.segment_volume` for the stages the
parameters steer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.rodset import Contacts, RodSet

__all__ = ["SegmentParams", "SegmentResult"]

#: the end of every "no rods found" message: what the user can change
_HINT = "check the contrast / pass --diameter"


@dataclass
class SegmentParams:
    """Every knob of :func:`segment_volume`.  Lengths are in voxels unless marked "x r" (radii).

    Attributes
    ----------
    diameter : float or None
        Rod diameter in voxels.  ``None``: estimated, coarsely from the maxima of the distance
        transform of the binarised foreground, then from the greyscale (median over rods of the
        intensity mass per unit length, with the contrast from a blurred-disc profile fit).
    smooth_sigma : float
        Gaussian denoising before binarisation and skeletonisation (detection only; the
        refinement reads the raw volume).  0 disables it.
    threshold : float or None
        Binarisation threshold in raw intensity units.  ``None``: half-way between the
        estimated background and foreground levels.
    contact_tolerance : float
        Largest surface gap (voxels) reported as a contact.
    contact_min_fill : float
        Image confirmation of a contact: the normalised intensity (0 = background,
        1 = foreground) on the segment joining the two rod surfaces must stay at or above this.
    junction_radius : float
        Skeleton voxels within ``junction_radius * r + 1`` of a junction (a voxel with 3 or more
        skeleton neighbours) are removed before the branches become seeds.
    min_seed_voxels : int
        Shortest skeleton branch (voxels) used as a seed.
    fit_iterations : int
        Iterations of the coarse centroid/line fit of each seed (and after each marching block).
    march_block : int
        Voxels probed at once when marching an axis outward (the line is refitted after every
        full block).
    march_fill : float
        Marching continues while the mean smoothed, normalised intensity in a disc of radius
        ``r / 2`` on the axis is at least this.
    split_anisotropy : float
        A fitted axis whose cross-section second moments differ by more than this times r^2 is
        two rods side by side: it is split into two seeds.
    residual_passes : int
        Rounds of seeding from foreground that no traced rod explains.
    merge_angle : float
        Pieces are pasted / deduplicated when their axes differ by at most this (degrees)...
    merge_distance : float
        ...the shorter one's ends lie within this (x r) of the longer one's axis...
    merge_gap : float
        ...and their extents overlap or leave a gap of at most this (x r) along the axis that
        the image shows filled.  (Independently, a piece whose axis lies for at least half its
        length within 0.75 r of another's is a duplicate of it, whatever the angle.)
    refine_iterations : int
        Most rounds of greyscale refinement (axis, then ends); 0 keeps the coarse fits.
    refine_tol : float
        Refinement stops when no rod end moves more than this (voxels) in a round; a rod is
        refined again only while it or a neighbour still moves.
    window_margin : float
        Voxels beyond the radius that the greyscale refinement reads around each axis (should
        cover about 2.5 blur sigmas).
    end_radius : float
        Radius (voxels) of the disc around the axis whose mean intensity profile locates ends.
    end_model : str
        ``"capsule"`` (rod ends are hemispherical caps, as ``rodwarp phantom`` and the simulator
        model them: the endpoint is the centre of the cap) or ``"flat"`` (the endpoint is the
        flat end face).
    min_length : float
        Rods shorter than this (x r) after refinement are rejected.
    min_fill : float
        Rods whose axis intensity plateau (normalised) is below this are rejected.
    radius_range : tuple of float
        Rods whose own greyscale radius falls outside this range (x the global r) are rejected.
    per_rod_radius : bool or None
        Give each rod its own greyscale radius (sub-voxel, from the intensity mass per unit
        length) in the output, the contact gaps and the acceptance tests, instead of the
        global one.  ``None``: when the radii are mixed (a broad distance-transform ridge, or
        a robust spread of the rods' own radii above ``MIXED_RADIUS_CV``).
    chunk : int or None
        Detection runs on overlapping cubes of this edge (voxels) read one at a time; ``None``
        processes the whole volume at once.  The refinement reads only the voxels around each rod.
    chunk_halo : int or None
        Overlap added on every side of a chunk; ``None``: ``max(4 smooth_sigma + 2, 3 r + 2)``.
    stats_block : int
        Edge of the blocks used for the level and coarse-radius statistics.
    dark : bool or None
        Rods darker than the background (grey values are negated first); ``None`` detects it
        from the histogram (:mod:`rodwarp.ct.segment._prepare`).
    fov : bool or None
        Field-of-view mask (a constant outside the reconstruction circle): ``None`` detects
        it, ``False`` never masks.
    background : bool or None
        Removal of the background trend about the rotation axis (cupping, rings): ``None``
        when it exceeds half the noise, ``True`` always, ``False`` never.
    shape : str
        ``"straight"`` (straight rods, two vertices each), ``"curved"`` (filaments traced as
        polylines, :mod:`rodwarp.ct.segment._curved`) or ``"auto"`` (curved when the skeleton's
        branches bend, see :func:`segment_volume`).
    """

    diameter: float | None = None
    smooth_sigma: float = 1.0
    threshold: float | None = None
    contact_tolerance: float = 1.0
    contact_min_fill: float = 0.5
    junction_radius: float = 1.0
    min_seed_voxels: int = 4
    fit_iterations: int = 3
    march_block: int = 12
    march_fill: float = 0.5
    split_anisotropy: float = 0.25
    residual_passes: int = 1
    merge_angle: float = 5.0
    merge_distance: float = 0.5
    merge_gap: float = 2.0
    refine_iterations: int = 8
    refine_tol: float = 0.02
    window_margin: float = 2.5
    end_radius: float = 2.0
    end_model: str = "capsule"
    min_length: float = 4.0
    min_fill: float = 0.6
    radius_range: tuple = (0.6, 1.5)
    per_rod_radius: bool | None = None
    chunk: int | None = None
    chunk_halo: int | None = None
    stats_block: int = 96
    dark: bool | None = None
    fov: bool | None = None
    background: bool | None = None
    shape: str = "auto"

    def validate(self) -> None:
        def pos(name, v, allow_zero=False):
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise _fail(f"segment parameter {name} must be a number, got {v!r}") from None
            if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
                raise _fail(f"segment parameter {name} must be {'>= 0' if allow_zero else '> 0'}, got {v!r}")
        if self.diameter is not None:
            pos("diameter", self.diameter)
            if self.diameter < 1.0:
                raise _fail(f"diameter {self.diameter} voxels is too small to segment; rods need at least 1 voxel")
        pos("smooth_sigma", self.smooth_sigma, True)
        pos("contact_tolerance", self.contact_tolerance, True)
        pos("contact_min_fill", self.contact_min_fill, True)
        pos("junction_radius", self.junction_radius, True)
        pos("march_fill", self.march_fill)
        pos("split_anisotropy", self.split_anisotropy)
        pos("merge_angle", self.merge_angle)
        pos("merge_distance", self.merge_distance)
        pos("merge_gap", self.merge_gap, True)
        pos("window_margin", self.window_margin)
        pos("end_radius", self.end_radius)
        pos("refine_tol", self.refine_tol)
        pos("min_length", self.min_length, True)
        pos("min_fill", self.min_fill, True)
        for name in ("min_seed_voxels", "fit_iterations", "march_block", "residual_passes",
                     "refine_iterations", "stats_block"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < (1 if name in ("march_block", "stats_block",
                                                                         "fit_iterations", "min_seed_voxels") else 0):
                raise _fail(f"segment parameter {name} must be a positive integer, got {v!r}")
        if self.end_model not in ("capsule", "flat"):
            raise _fail(f"end_model must be 'capsule' or 'flat', got {self.end_model!r}")
        if self.chunk is not None and (not isinstance(self.chunk, (int, np.integer)) or self.chunk < 16):
            raise _fail(f"chunk must be an integer >= 16 voxels or None, got {self.chunk!r}")
        if self.chunk_halo is not None and (not isinstance(self.chunk_halo, (int, np.integer)) or self.chunk_halo < 0):
            raise _fail(f"chunk_halo must be a non-negative integer or None, got {self.chunk_halo!r}")
        if self.shape not in ("straight", "curved", "auto"):
            raise _fail(f"shape must be 'straight', 'curved' or 'auto', got {self.shape!r}")
        for name in ("dark", "fov", "background"):
            if getattr(self, name) not in (None, True, False):
                raise _fail(f"segment parameter {name} must be true, false or None (detect), got {getattr(self, name)!r}")
        lo, hi = self.radius_range
        if not (0 <= lo < hi):
            raise _fail(f"radius_range must be (low, high) with 0 <= low < high, got {self.radius_range!r}")


@dataclass
class SegmentResult:
    """What :func:`segment_volume` found.

    Attributes
    ----------
    rods : RodSet
        Straight rods in voxel units (2 vertices each, ``(x, y, z)``), one radius per rod;
        ``rods.contacts`` is ``contacts``.
    contacts : Contacts
        Contacts in voxel units (point = midpoint of the two closest axis points; gap = surface gap).
    diameter : float
        Rod diameter in voxels (estimated or given).
    timings : dict
        Seconds per stage that ran, under its name (``prepare``, ``stats``, ``detect``, ``merge``,
        ``refine``, ``contacts``, ``doubt``; ``filaments`` on the curved path), and ``total``.
    quality : dict
        Fit and detection figures (see :func:`segment_volume`); ``quality["flags"]`` lists, in
        words, what makes the output untrustworthy (empty when nothing does).
    spacing : float
        Edge of the working voxel in the units of the ``voxel_size`` given (1 without one):
        physical coordinates are ``rods.points * spacing``.
    doubt : rodwarp.ct.segment._doubt.Doubt, optional
        Per-rod confidence and the foreground no trace explains (``quality["unexplained"]``
        holds its summary).
    """

    rods: RodSet
    contacts: Contacts
    diameter: float
    timings: dict = field(default_factory=dict)
    quality: dict = field(default_factory=dict)
    spacing: float = 1.0
    doubt: object = None
