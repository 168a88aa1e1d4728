"""CT of rod packings: volume files, synthetic phantoms with ground truth, and segmentation.

>>> from rodwarp import ct
>>> vol = ct.read_volume("scan.tif")                                    # doctest: +SKIP
>>> result = ct.segment_volume(vol, ct.SegmentParams(), voxel_size=0.05)   # doctest: +SKIP
>>> result.rods, result.contacts                                         # doctest: +SKIP

Volumes are indexed ``(z, y, x)`` = (slice, row, column); points are ``(x, y, z)`` with the
centre of voxel ``(0, 0, 0)`` at the origin.  Three subpackages, each with its own public face;
their public names are re-exported here, flat:

==================  =============================================================================
``io``              volume files: :func:`read_volume` (TIFF, folders of slices, zarr), lazy
                    access, :func:`write_tiff`, voxel sizes from the metadata
``phantom``         phantoms with their truth: :func:`render_phantom`, scenes, realistic-scan
                    cases (:func:`make_case`), :func:`make_phantom` (``rodwarp phantom``)
``segment``         :func:`segment_volume`, a list of stages (:data:`DEFAULT_STAGES`,
                    :class:`Stage`, :func:`insert_stage`); scoring against a truth;
                    :func:`run_segment` (``rodwarp segment``)
``_voxels``         shared by all three: geometry in voxel space, voxel-size parsing
==================  =============================================================================

Modules inside a subpackage are private to it; the subpackages use each other through these
faces only.  Nothing under ``rodwarp.ct`` imports Warp (``tests/test_ct_imports.py``); names
load on first use.
"""

from rodwarp._util import lazy_exports

_WHERE = {
    # volume files
    "read_volume": "io", "open_volume_lazy": "io", "write_tiff": "io", "list_slices": "io", "check_volume": "io",
    "read_voxel_size": "io", "read_voxel_unit": "io", "read_voxel_ratio": "io",
    # phantoms
    "render_phantom": "phantom", "occupancy": "phantom", "phantom_truth": "phantom", "write_phantom": "phantom",
    "truth_paths": "phantom", "make_phantom": "phantom", "PhantomOptions": "phantom", "capsule_volume": "phantom",
    "DEFAULT_TOLERANCE_VOXELS": "phantom", "SCENES": "phantom",
    "scene_isolated": "phantom", "scene_crossing_pair": "phantom", "scene_parallel_pair": "phantom",
    "scene_random_packing": "phantom", "scene_bundles": "phantom", "scene_arcs": "phantom",
    "scene_wire_tangle": "phantom",
    "ScanCase": "phantom", "CASES": "phantom", "make_case": "phantom", "crop_straight": "phantom",
    "scored_subset": "phantom", "check_phantom": "phantom", "check_phantom_out": "phantom",
    # segmentation
    "SegmentParams": "segment", "SegmentOptions": "segment", "SegmentResult": "segment",
    "Stage": "segment", "SegmentContext": "segment", "DEFAULT_STAGES": "segment", "insert_stage": "segment",
    "prepare_volume": "segment", "Prepared": "segment",
    "cross_section": "segment", "looks_bundled": "segment", "fit_discs": "segment",
    "trace_filaments": "segment", "FilamentResult": "segment",
    "segment_volume": "segment", "AUTO_BEND_FRACTION": "segment",
    # scoring and the command's files
    "RodMatch": "segment", "match_rods": "segment", "ContactScore": "segment", "score_contacts": "segment",
    "PolylineMatch": "segment", "match_polylines": "segment", "resample_polyline": "segment",
    "run_segment": "segment", "write_outputs": "segment", "to_physical": "segment", "write_rods_csv": "segment",
    "write_contacts_csv": "segment", "plot_qa_slices": "segment", "plot_qa_projection": "segment",
    "default_out": "segment", "check_segment": "segment",
    # voxel sizes
    "parse_voxel_size": "_voxels", "parse_voxel_size_text": "_voxels",
}

__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_exports(__name__, _WHERE)
