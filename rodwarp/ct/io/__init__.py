"""CT volume files: reading (multi-page TIFF, folders of slices, zarr), lazy access, writing, metadata.

>>> from rodwarp.ct.io import read_volume, read_voxel_size
>>> vol = read_volume("scan.tif")                         # doctest: +SKIP

Volumes are indexed ``(z, y, x)`` = (slice, row, column); voxel sizes are ``(dz, dy, dx)`` in
the file's unit (:func:`read_voxel_unit`).

================  ================================================================================
``_volume_io``    :func:`read_volume`, :func:`open_volume_lazy`, :func:`check_volume`
``_volume_meta``  a volume's files (:func:`list_slices`), :func:`write_tiff`, voxel sizes and unit
================  ================================================================================

Names load on first use.
"""

from rodwarp._util import lazy_exports

_WHERE = {
    "read_volume": "_volume_io", "open_volume_lazy": "_volume_io", "check_volume": "_volume_io",
    "write_tiff": "_volume_meta", "list_slices": "_volume_meta", "read_voxel_size": "_volume_meta",
    "read_voxel_unit": "_volume_meta", "read_voxel_ratio": "_volume_meta",
}

__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_exports(__name__, _WHERE)
