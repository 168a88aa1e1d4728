"""CT of rod packings: volume files, synthetic phantoms with ground truth, and segmentation.

>>> from rodwarp import ct
>>> vol = ct.read_volume("scan.tif")                                    # doctest: +SKIP
>>> result = ct.segment_volume(vol, ct.SegmentParams(), voxel_size=0.05)   # doctest: +SKIP
>>> result.rods, result.contacts                                         # doctest: +SKIP

Volumes are indexed ``(z, y, x)`` = (slice, row, column); points are ``(x, y, z)`` with the
centre of voxel ``(0, 0, 0)`` at the origin.  One private module per job, their public names
re-exported here (scikit-image's layout); segmentation is split by stage, in the order
:func:`segment_volume` runs them:

===================  ============================================================================
``_volume_io``       reading multi-page TIFF, folders of slices, zarr (:func:`read_volume`)
``_volume_meta``     a volume's files, :func:`write_tiff`, voxel sizes from the metadata
``_phantom``         a phantom's truth, files and command (:func:`make_phantom`)
``_phantom_render``  :func:`render_phantom`: partial volume, blur, noise, artefacts
``_scenes``          phantom scenes in voxel units (random packings, bundles, arcs, wires)
``_cases``           realistic-scan cases with their truth (:func:`make_case`)
``_params``          :class:`SegmentParams`, :class:`SegmentOptions`, :class:`SegmentResult`
``_prepare``         0 - field-of-view mask, background trend, dark rods, anisotropic voxels
``_binary``          0, 1, 4 - binarised stacks: two levels recognised, the rods' mask, its radii
``_levels``          1 - levels and binarisation (background, plateau, threshold, coarse radius)
``_seeds``           2 - seeds: straight pieces of the skeleton, junctions removed
``_tracing``         2 - cylinder fits and marching (``_bundles``: bundles of touching rods)
``_pasting``         3 - pieces of one rod pasted, duplicates made one
``_refine``          4 - axes, radii and ends against the greyscale (``_profile``: blurred rods)
``_contacts``        5 - contact candidates confirmed by the image
``_curved``          curved filaments traced as polylines (``shape="curved"``)
``_segment``         :func:`segment_volume`, the driver
``_score``           :func:`match_rods`, :func:`match_polylines`, :func:`score_contacts`
``_report``          :func:`run_segment`: the files of ``rodwarp segment``
``_checks``          :func:`check_phantom`, :func:`check_segment`: the commands' options, before any work
===================  ============================================================================

Shared helpers: ``_reader`` (lazy volume access) and ``_voxels`` (geometry in voxel space).
Nothing here imports warp; names load on first use.
"""

from rodwarp._util import lazy_exports

_WHERE = {
    # volume files
    "read_volume": "_volume_io", "open_volume_lazy": "_volume_io", "write_tiff": "_volume_meta",
    "list_slices": "_volume_meta", "check_volume": "_volume_io", "read_voxel_size": "_volume_meta",
    "read_voxel_unit": "_volume_meta",
    # phantoms
    "render_phantom": "_phantom_render", "occupancy": "_phantom_render", "phantom_truth": "_phantom",
    "write_phantom": "_phantom", "truth_paths": "_phantom", "make_phantom": "_phantom", "PhantomOptions": "_phantom",
    "capsule_volume": "_phantom_render", "DEFAULT_TOLERANCE_VOXELS": "_phantom", "SCENES": "_phantom",
    "scene_isolated": "_scenes", "scene_crossing_pair": "_scenes", "scene_parallel_pair": "_scenes",
    "scene_random_packing": "_scenes", "scene_bundles": "_scenes", "scene_arcs": "_scenes",
    "scene_wire_tangle": "_scenes",
    "ScanCase": "_cases", "CASES": "_cases", "make_case": "_cases", "crop_straight": "_cases",
    "scored_subset": "_cases",
    # segmentation
    "SegmentParams": "_params", "SegmentOptions": "_params", "SegmentResult": "_params",
    "prepare_volume": "_prepare", "parse_voxel_size": "_prepare", "Prepared": "_prepare",
    "cross_section": "_bundles", "looks_bundled": "_bundles", "fit_discs": "_bundles",
    "trace_filaments": "_curved", "FilamentResult": "_curved",
    "segment_volume": "_segment", "AUTO_BEND_FRACTION": "_segment",
    # scoring and the command's files
    "RodMatch": "_score", "match_rods": "_score", "ContactScore": "_score", "score_contacts": "_score",
    "PolylineMatch": "_score", "match_polylines": "_score", "resample_polyline": "_score",
    "run_segment": "_report", "write_outputs": "_report", "to_physical": "_report", "write_rods_csv": "_report",
    "write_contacts_csv": "_report", "plot_qa_slices": "_report", "plot_qa_projection": "_report",
    "parse_voxel_size_text": "_report", "default_out": "_report",
    "check_phantom": "_checks", "check_segment": "_checks",
}

__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_exports(__name__, _WHERE)
