"""Synthetic CT phantoms of rod sets with their ground truth: rendering, scenes, realistic-scan cases,
the ``rodwarp phantom`` command and the files it owns.

>>> from rodwarp.ct.phantom import scene_random_packing, render_phantom
>>> rods = scene_random_packing((64, 64, 64), n_rods=10, radius=3, aspect=6)   # doctest: +SKIP
>>> vol = render_phantom(rods, (64, 64, 64), cnr=5)                          # doctest: +SKIP

Volumes are indexed ``(z, y, x)``; points are ``(x, y, z)`` with the centre of voxel
``(0, 0, 0)`` at the origin.

===================  ============================================================================
``_phantom_render``  :func:`render_phantom`: partial volume, blur, noise, artefacts
``_truth``           :func:`phantom_truth` (true contacts), :func:`truth_paths`
``_scenes``          scenes in voxel units (random packings, bundles, arcs, wires)
``_phantom``         :func:`write_phantom`, :func:`make_phantom` (the command), :class:`PhantomOptions`
``_phantom_owner``   who owns a phantom's files (:func:`check_phantom_out`, the truth manifest)
``_cases``           realistic-scan cases with their truth (:func:`make_case`)
``_checks``          :func:`check_phantom`: the command's options, before any work
===================  ============================================================================

Names load on first use.
"""

from rodwarp._util import lazy_exports

_WHERE = {
    "render_phantom": "_phantom_render", "occupancy": "_phantom_render", "capsule_volume": "_phantom_render",
    "phantom_truth": "_truth", "truth_paths": "_truth", "DEFAULT_TOLERANCE_VOXELS": "_truth",
    "write_phantom": "_phantom", "make_phantom": "_phantom", "PhantomOptions": "_phantom", "SCENES": "_phantom",
    "scene_isolated": "_scenes", "scene_crossing_pair": "_scenes", "scene_parallel_pair": "_scenes",
    "scene_random_packing": "_scenes", "scene_bundles": "_scenes", "scene_arcs": "_scenes",
    "scene_wire_tangle": "_scenes",
    "ScanCase": "_cases", "CASES": "_cases", "make_case": "_cases", "crop_straight": "_cases",
    "scored_subset": "_cases",
    "check_phantom": "_checks",
    "check_phantom_out": "_phantom_owner", "read_truth_meta": "_phantom_owner", "PHANTOM_FORMAT": "_phantom_owner",
}

__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_exports(__name__, _WHERE)
