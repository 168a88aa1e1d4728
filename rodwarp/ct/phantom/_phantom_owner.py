"""Who owns a phantom's files: the TIFF ``rodwarp phantom --out`` names and its truth beside it.

A phantom is three files, ``STACK.tif``, ``STACK_truth.npz`` and ``STACK_truth.json``. The
truth JSON is the phantom's manifest (:data:`PHANTOM_FORMAT`): written with ``complete``
false before the TIFF and the rods, and again with ``complete`` true as the last act, so a
kill while a phantom is written leaves a truth that says it is incomplete, never a TIFF of one
phantom beside the truth of another passing as whole. The rules of
:mod:`rodwarp.rodset.rundir` carry over: an earlier phantom at the same path is replaced; a
file that is not a rodwarp phantom (a real scan), or a folder that another command's run owns,
is refused unless ``overwrite``.
"""

from __future__ import annotations

import json
from pathlib import Path

from rodwarp.ct.phantom._truth import truth_paths as _truth_paths
from rodwarp.errors import RodwarpError

#: ``format`` of a phantom's truth JSON
PHANTOM_FORMAT = "rodwarp-phantom-truth"


def read_truth_meta(path_tif) -> dict | None:
    """The truth JSON of the phantom at ``path_tif`` (None when there is none, or it is not
    a rodwarp phantom's)."""
    js = _truth_paths(path_tif)[1]
    try:
        meta = json.loads(js.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(meta, dict):
        return None
    # phantoms written before the format key carry their rods' file name instead
    if meta.get("format") == PHANTOM_FORMAT or ("truth_rods" in meta and "voxel_size_zyx_m" in meta):
        return meta
    return None


def check_phantom_out(path_tif, *, overwrite: bool = False) -> None:
    """Refuse, before any work, a phantom ``--out`` that would replace what is not a phantom.

    Parameters
    ----------
    path_tif : path-like
        The TIFF to write.
    overwrite : bool
        Replace the file(s) at ``path_tif`` and beside it whatever they are.

    Raises
    ------
    RodwarpError
        ``path_tif`` (or its truth files) exists and is not a rodwarp phantom, or its folder is
        the run folder of another command (``rodwarp-run.json``).
    """
    from rodwarp.rodset import rundir

    tif = Path(path_tif)
    if overwrite:
        return
    folder = tif.parent
    m = rundir.read_manifest(folder)
    if m is not None:
        raise RodwarpError(f"--out {tif}: {folder} is the folder of {rundir._describe(m)}; a phantom there would "
                           "mix with its outputs: choose another --out, or pass --overwrite")
    npz, js = _truth_paths(tif)
    existing = [p for p in (tif, npz, js) if p.exists() or p.is_symlink()]
    if existing and read_truth_meta(tif) is None:
        raise RodwarpError(f"--out {tif}: {existing[0]} exists and is not a rodwarp phantom (no {js.name} of "
                           f"`rodwarp phantom` beside it); choose another --out, or pass --overwrite to replace it")


def mark_truth(path_tif, *, complete: bool, **extra) -> None:
    """Write the phantom's truth JSON as its manifest: ``complete`` false before its files are
    written, true (with every truth field in ``extra``) as the last act."""
    from rodwarp.rodset.files import write_json

    js = _truth_paths(path_tif)[1]
    write_json(js, {"format": PHANTOM_FORMAT, "complete": bool(complete),
                    "status": "complete" if complete else "writing", **extra})
