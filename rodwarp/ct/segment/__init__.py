"""CT segmentation: rod axes, radii and contacts (or curved filaments) from a greyscale volume, run as a
list of stages, and the files of ``rodwarp segment``.

>>> from rodwarp.ct.segment import segment_volume, SegmentParams
>>> result = segment_volume(vol, SegmentParams(), voxel_size=0.05)          # doctest: +SKIP

Points are ``(x, y, z)`` in working voxels with the centre of voxel ``(0, 0, 0)`` at the origin.
:func:`segment_volume` runs :data:`DEFAULT_STAGES` (or the list it is given) on one
:class:`SegmentContext`; add a stage with :func:`insert_stage` (see ``_stages``).

=============  ===================================================================================
``_params``    :class:`SegmentParams` (the knobs), :class:`SegmentResult`
``_options``   :class:`SegmentOptions` of ``rodwarp segment`` and :func:`check_segment`
``_stages``    :class:`Stage`, :class:`SegmentContext`, :data:`DEFAULT_STAGES`, :func:`insert_stage`
``_segment``   :func:`segment_volume`, the driver: runs the stages, composes quality and flags
``_reader``    block access to a (lazy) volume, with a cache
``_prepare``   stage prepare: field-of-view mask, background trend, dark rods, anisotropic voxels
``_binary``    binarised stacks: two levels recognised, the rods' mask, its radii
``_levels``    stage stats: background, plateau, threshold, coarse radius
``_seeds``     stage detect: straight pieces of the skeleton, junctions removed
``_tracing``   stage detect: cylinder fits and marching (``_bundles``: bundles of touching rods)
``_curved``    stage filaments: curved filaments as polylines (``_bridging``: joins across junctions)
``_pasting``   stage merge: pieces of one rod pasted, duplicates made one
``_refine``    stage refine: axes, radii and ends against the greyscale (``_profile``: blurred rods)
``_contacts``  stage contacts: contact candidates confirmed by the image
``_doubt``     stage doubt: per-rod confidence, foreground no trace explains
``_score``     :func:`match_rods`, :func:`match_polylines`, :func:`score_contacts` against a truth
``_report``    :func:`run_segment`: the files of ``rodwarp segment``
=============  ===================================================================================

Names load on first use.
"""

from rodwarp._util import lazy_exports

_WHERE = {
    "SegmentParams": "_params", "SegmentResult": "_params",
    "SegmentOptions": "_options", "check_segment": "_options",
    "Stage": "_stages", "SegmentContext": "_stages", "DEFAULT_STAGES": "_stages", "insert_stage": "_stages",
    "segment_volume": "_segment", "AUTO_BEND_FRACTION": "_segment", "MIN_EDGE_VOXELS": "_segment",
    "prepare_volume": "_prepare", "Prepared": "_prepare",
    "cross_section": "_bundles", "looks_bundled": "_bundles", "fit_discs": "_bundles",
    "trace_filaments": "_curved", "FilamentResult": "_curved",
    "Doubt": "_doubt", "DOUBT_CONFIDENCE": "_doubt", "doubt_kind": "_doubt",
    "RodMatch": "_score", "match_rods": "_score", "ContactScore": "_score", "score_contacts": "_score",
    "PolylineMatch": "_score", "match_polylines": "_score", "resample_polyline": "_score",
    "run_segment": "_report", "write_outputs": "_report", "to_physical": "_report", "write_rods_csv": "_report",
    "write_contacts_csv": "_report", "write_filaments_csv": "_report", "plot_qa_slices": "_report",
    "plot_qa_projection": "_report", "plot_qa_confidence": "_report", "default_out": "_report",
}

__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_exports(__name__, _WHERE)
