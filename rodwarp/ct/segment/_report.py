"""Outputs of ``rodwarp segment``: the rod set in physical units, CSV tables, summary, QA figures.

Files written in the output directory (each atomically):

``rods.npz``       the rod set (rod-set format, physical units, contacts included)
``rods.csv``       ``rod,x,y,z,radius`` one row per vertex (physical units)
``contacts.csv``   ``rod_i,rod_j,x,y,z,gap`` one row per contact (physical units)
``summary.json``   counts, diameter, voxel size, timings, quality figures, every parameter;
                   ``binarised``: the stack held two grey levels and was segmented from its
                   mask (``quality.binarised`` names the levels and the rods' one)
``qa_slices.png``  three slices with the fitted centrelines (and their radius) drawn over the image
``qa_projection.png``  maximum-intensity projections along z and y with every rod and contact
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from rodwarp._util import progress_bar, versions
from rodwarp.errors import RodwarpError
from rodwarp.ct._voxels import parse_voxel_size_text
from rodwarp.rodset import UNITS, RodSet
from rodwarp.rodset.commands import SEGMENT_OUTPUTS
from rodwarp.rodset.files import save_figure, write_json, write_text


def to_physical(rods: RodSet, voxel_size: float, units: str) -> RodSet:
    """Voxel-unit rods (x = column, y = row, z = slice) scaled by the voxel size.

    Parameters
    ----------
    voxel_size : float
        Edge length of one voxel, in ``units``.
    units : str
        ``m``, ``mm``, ``um`` (scaled) or ``voxel`` (left as is; ``voxel_size`` must then be 1).
    """
    if units not in UNITS:
        raise RodwarpError(f"unknown units '{units}'; use one of {', '.join(UNITS)}")
    if not (np.isfinite(voxel_size) and voxel_size > 0):
        raise RodwarpError(f"--voxel-size must be a positive number, got {voxel_size:g}")
    if units == "voxel":
        if voxel_size != 1.0:
            raise RodwarpError("with --units voxel the voxel size is 1 by definition; drop --voxel-size or pick m, mm, um")
        return rods.copy()
    return rods.to_units(units, voxel_size=voxel_size * UNITS[units])


def _csv_text(header: list[str], rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([repr(float(v)) if isinstance(v, (float, np.floating)) else int(v) for v in r])
    return buf.getvalue()


def write_rods_csv(path, rods: RodSet) -> Path:
    """``rod,x,y,z,radius``, one row per vertex, in the rod set's units: the rod-set CSV format,
    written by its one writer (:func:`rodwarp.rodset.save_csv`)."""
    from rodwarp.rodset import save_csv

    return save_csv(rods, path)


def write_contacts_csv(path, rods: RodSet) -> Path:
    """``rod_i,rod_j,x,y,z,gap``, one row per contact, in the rod set's units."""
    c = rods.contacts
    rows = [] if c is None else ((int(c.rod_i[k]), int(c.rod_j[k]), *c.point[k], c.gap[k]) for k in range(len(c)))
    write_text(path, _csv_text(["rod_i", "rod_j", "x", "y", "z", "gap"], rows))
    return Path(path)


def _display(volume, z: int) -> np.ndarray:
    sl = np.asarray(volume[z], dtype=np.float64)
    return sl


def plot_qa_slices(path, volume, rods_vox: RodSet, *, slices=None) -> Path:
    """Slices of the volume with the fitted centrelines (voxel units) drawn where they cross.

    Each rod is drawn over the slice where its axis lies within one radius of the slice plane
    (solid), so a correct fit sits on the middle of every bright rod section.
    """
    from matplotlib.figure import Figure

    nz = volume.shape[0]
    if slices is not None:
        zs = list(slices)
    elif rods_vox.n_rods:
        # spread over the slices the rods occupy (a small packing in a big volume stays visible)
        zlo, zhi = float(rods_vox.points[:, 2].min()), float(rods_vox.points[:, 2].max())
        zs = sorted({int(np.clip(round(zlo + q * (zhi - zlo)), 0, nz - 1)) for q in (0.25, 0.5, 0.75)})
    else:
        zs = [int(nz * q) for q in (0.25, 0.5, 0.75)]
    fig = Figure(figsize=(5.2 * len(zs), 5.4))
    p0, p1, rod = rods_vox.segments()
    r = rods_vox.radii[rod]
    for k, z0 in enumerate(zs):
        ax = fig.add_subplot(1, len(zs), k + 1)
        img = _display(volume, z0)
        lo, hi = np.percentile(img, [1, 99.5])
        ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, origin="upper")
        for a, b, ri in zip(p0, p1, r):
            # the part of segment a-b within |z - z0| <= r
            dz = b[2] - a[2]
            if abs(dz) < 1e-12:
                if abs(a[2] - z0) > ri:
                    continue
                t0, t1 = 0.0, 1.0
            else:
                ta, tb = (z0 - ri - a[2]) / dz, (z0 + ri - a[2]) / dz
                t0, t1 = max(min(ta, tb), 0.0), min(max(ta, tb), 1.0)
                if t1 <= t0:
                    continue
            q0, q1 = a + t0 * (b - a), a + t1 * (b - a)
            ax.plot([q0[0], q1[0]], [q0[1], q1[1]], "-", color="tab:red", lw=1.6)
        ax.set_title(f"slice z = {z0}: fitted axes within one radius")
        ax.set_xlabel("x (column)")
        ax.set_ylabel("y (row)")
        ax.set_xlim(-0.5, img.shape[1] - 0.5)
        ax.set_ylim(img.shape[0] - 0.5, -0.5)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_qa_projection(path, volume, rods_vox: RodSet) -> Path:
    """Maximum-intensity projections along z and y with every fitted rod and contact."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 6))
    p0, p1, rod = rods_vox.segments()
    rng = np.random.default_rng(0)
    colours = rng.uniform(0.2, 1.0, (max(rods_vox.n_rods, 1), 3))
    c = rods_vox.contacts
    for k, (axis, (i, j), name) in enumerate(((0, (0, 1), "along z (x-y)"), (1, (0, 2), "along y (x-z)"))):
        ax = fig.add_subplot(1, 2, k + 1)
        mip = _mip(volume, axis)
        lo, hi = np.percentile(mip, [1, 99.5])
        ax.imshow(mip, cmap="gray", vmin=lo, vmax=hi, origin="upper", alpha=0.8)
        for a, b, ri in zip(p0, p1, rod):
            ax.plot([a[i], b[i]], [a[j], b[j]], "-", color=colours[ri], lw=1.2)
        if c is not None and len(c):
            ax.plot(c.point[:, i], c.point[:, j], "o", ms=3, color="yellow", label=f"{len(c)} contacts")
            ax.legend(loc="upper right", fontsize=8)
        ax.set_title(f"maximum projection {name}: {rods_vox.n_rods} rods")
        ax.set_xlabel("x (column)")
        ax.set_ylabel("y (row)" if axis == 0 else "z (slice)")
    fig.tight_layout()
    return save_figure(fig, path)


def write_filaments_csv(path, rods: RodSet, doubt) -> Path:
    """``rod,length,radius,confidence,support,crowding,open_ends,doubts``: one row per rod or
    filament (lengths and radii in the rod set's units; ``doubts`` joined with "; ")."""
    L = rods.rod_lengths()
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["rod", "length", "radius", "confidence", "support", "crowding", "open_ends", "doubts"])
    for k in range(rods.n_rods):
        w.writerow([k, repr(float(L[k])), repr(float(rods.radii[k])), f"{doubt.confidence[k]:.3f}",
                    f"{doubt.support[k]:.3f}", f"{doubt.crowding[k]:.3f}", int(doubt.open_ends[k]),
                    "; ".join(doubt.doubts[k])])
    return write_text(path, buf.getvalue())


def plot_qa_confidence(path, rods_vox: RodSet, doubt) -> Path:
    """Projections along z and y of the binarised foreground's depth (grey), the depth of the
    foreground no trace explains (magenta) and every trace coloured by its confidence (thick:
    doubtful, numbered)."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    from rodwarp.ct.segment._doubt import DOUBT_CONFIDENCE

    fig = Figure(figsize=(13, 6))
    p0, p1, rod = rods_vox.segments()
    cmap = colormaps["RdYlGn"]
    norm = Normalize(0.0, 1.0)
    q = doubt.summary()
    axes = []
    for k, (mip, (i, j), name) in enumerate(((doubt.mip_z, (0, 1), "along z (x-y)"),
                                              (doubt.mip_y, (0, 2), "along y (x-z)"))):
        ax = fig.add_subplot(1, 2, k + 1)
        axes.append(ax)
        # foreground depth in grey; unexplained depth in magenta, opaque at its 99th percentile
        fgd = mip[0].astype(float)
        ax.imshow(fgd, cmap="gray", vmin=0, vmax=max(float(np.percentile(fgd, 99.5)), 1.0), origin="upper",
                  interpolation="nearest")
        und = mip[1].astype(float)
        top = max(float(np.percentile(und[und > 0], 99)) if np.any(und > 0) else 1.0, 1.0)
        over = np.zeros(und.shape + (4,))
        over[..., 0] = over[..., 2] = 1.0
        over[..., 3] = np.clip(und / top, 0.0, 1.0) * 0.85
        ax.imshow(over, origin="upper", interpolation="nearest")
        conf = doubt.confidence
        for a, b, ri in zip(p0, p1, rod):
            ax.plot([a[i], b[i]], [a[j], b[j]], "-", color=cmap(norm(conf[ri])),
                    lw=2.2 if conf[ri] < DOUBT_CONFIDENCE else 1.2)
        for ri in doubt.doubtful:
            c = rods_vox.rod(int(ri)).mean(0)
            ax.text(c[i], c[j], str(int(ri)), color="white", fontsize=7, ha="center", va="center")
        ax.set_title(f"projection {name}")
        ax.set_xlabel("x (column)")
        ax.set_ylabel("y (row)" if k == 0 else "z (slice)")
    import matplotlib.cm as cm

    sm = cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=axes, fraction=0.025, label="trace confidence")
    fig.suptitle(f"{rods_vox.n_rods} traces, {q['doubtful']} doubtful (confidence < {DOUBT_CONFIDENCE:g}, numbered); "
                 f"unexplained foreground (magenta) {100 * q['fraction']:.1f}% in {q['regions']} regions; "
                 f"grey: foreground depth")
    return save_figure(fig, path)


def _mip(volume, axis: int, block: int = 64) -> np.ndarray:
    """Maximum projection of a (possibly lazy) volume, a block of slices at a time."""
    nz = volume.shape[0]
    if axis == 0:
        out = None
        for z in range(0, nz, block):
            m = np.asarray(volume[z:z + block]).max(axis=0)
            out = m if out is None else np.maximum(out, m)
        return out.astype(np.float64)
    parts = [np.asarray(volume[z:z + block]).max(axis=1) for z in range(0, nz, block)]
    return np.concatenate(parts, axis=0).astype(np.float64)


def write_outputs(outdir, result, volume, *, voxel_size: float, units: str, summary: dict,
                  figures: bool = True, grid_scale=None) -> dict:
    """Write every output of ``rodwarp segment`` and return the summary written.

    Parameters
    ----------
    outdir : path-like
        Output directory (created).
    result : SegmentResult
        Rods and contacts in voxel units.
    volume : array-like (z, y, x)
        The scanned volume (for the QA figures).
    voxel_size, units
        Scale of the outputs (see :func:`to_physical`): the edge of the result's (working) voxel.
    summary : dict
        Extra fields (input, parameters, timings) merged into ``summary.json``.
    grid_scale : (sx, sy, sz), optional
        Input voxels per working voxel along x, y, z (an anisotropic scan was resampled): the
        QA figures draw the rods over the input's slices.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    rods_vox = result.rods.copy()
    rods_vox.contacts = result.contacts
    phys = to_physical(rods_vox, voxel_size, units)
    phys.attrs = {**phys.attrs, "voxel_size": voxel_size, "voxel_size_units": units,
                  "coordinates": "x = column, y = row, z = slice index, times the voxel size; "
                                 "origin at the centre of the first voxel"}
    phys.save(outdir / "rods.npz")
    write_rods_csv(outdir / "rods.csv", phys)
    write_contacts_csv(outdir / "contacts.csv", phys)
    doubt = getattr(result, "doubt", None)
    if doubt is not None:
        write_filaments_csv(outdir / "filaments.csv", phys, doubt)
    out = dict(summary)
    out.update({
        "n_rods": int(phys.n_rods),
        "n_contacts": int(len(result.contacts)),
        "contacts_per_rod": 2.0 * len(result.contacts) / max(phys.n_rods, 1),
        "diameter_voxels": float(result.diameter),
        "diameter": float(result.diameter) * (voxel_size if units != "voxel" else 1.0),
        "units": units,
        "voxel_size": voxel_size,
        "mean_rod_length": float(np.mean(phys.rod_lengths())) if phys.n_rods else 0.0,
        "timings_s": result.timings,
        "quality": result.quality,
        "files": ["rods.npz", "rods.csv", "contacts.csv", "summary.json"],
    })
    out["shape"] = result.quality.get("shape", "straight")
    if doubt is not None:
        out["files"].insert(3, "filaments.csv")
        L = phys.rod_lengths()
        out["filaments"] = [{"rod": k, "length": float(L[k]), "radius": float(phys.radii[k]),
                             "confidence": float(doubt.confidence[k]), "doubts": doubt.doubts[k]}
                            for k in range(phys.n_rods)]
    if figures:
        qa = rods_vox
        if grid_scale is not None and not np.allclose(grid_scale, 1.0):
            qa = rods_vox.copy()
            qa.points = qa.points * np.asarray(grid_scale, float)
            if qa.contacts is not None:
                qa.contacts.point = qa.contacts.point * np.asarray(grid_scale, float)
        plot_qa_slices(outdir / "qa_slices.png", volume, qa)
        plot_qa_projection(outdir / "qa_projection.png", volume, qa)
        out["files"] += ["qa_slices.png", "qa_projection.png"]
        if doubt is not None and doubt.mip_z is not None:
            plot_qa_confidence(outdir / "qa_confidence.png", rods_vox, doubt)
            out["files"].append("qa_confidence.png")
    write_json(outdir / "summary.json", out)
    return out


def default_out(stack) -> Path:
    """``segment/`` beside the stack (a file or a folder of slices)."""
    p = Path(stack)
    return p.parent / "segment"


def run_segment(stack, *, voxel_size=None, units: str | None = None, diameter: float | None = None, out=None,
                chunk: int | None = None, contact_tolerance: float = 1.0, figures: bool = True,
                progress: bool = False, params=None, overwrite: bool = False) -> dict:
    """Read a CT stack, segment it and write every output (the ``rodwarp segment`` command).

    Parameters
    ----------
    stack : path-like
        Multi-page TIFF, folder of slice TIFFs, or zarr array.
    voxel_size : float, sequence of 3 floats, str or None
        Voxel edge in ``units`` (one value), or edges along (z, y, x); a string ``"0.05"`` or
        ``"0.1,0.05,0.05"``.  ``None``: read from the stack's metadata (ImageJ / OME-TIFF,
        OME-Zarr, :func:`rodwarp.ct.read_voxel_size`).
    units : str, optional
        Unit of ``voxel_size``, ``diameter`` and every output length; default ``mm`` (or, with
        the voxel size from metadata, the unit the ImageJ metadata states it in when m, mm or
        um, else ``mm`` for voxels of 0.1 mm and more and ``um`` below).
    diameter : float, optional
        Rod diameter in ``units``; estimated from the image when absent.
    chunk : int, optional
        Edge (voxels) of the overlapping chunks for volumes larger than memory.
    contact_tolerance : float
        Largest surface gap counted as a contact, in (working) voxels.
    params : SegmentParams, optional
        Every other knob of the segmenter.
    overwrite : bool
        Write into ``out`` even when it holds another command's run (:mod:`rodwarp.rodset.rundir`;
        an earlier segmentation there is always replaced).
    """
    import time
    from dataclasses import asdict, replace

    from rodwarp.ct.io import open_volume_lazy, read_voxel_size
    from rodwarp.ct.segment._params import SegmentParams
    from rodwarp.ct.segment._segment import segment_volume
    from rodwarp.rodset import rundir

    t0 = time.perf_counter()
    if units is not None and units not in UNITS:
        raise RodwarpError(f"unknown units '{units}'; use one of {', '.join(UNITS)}")
    if diameter is not None and not (np.isfinite(diameter) and diameter > 0):
        raise RodwarpError(f"--diameter must be a positive number, got {diameter:g}")
    if chunk is not None and chunk < 16:
        raise RodwarpError(f"--chunk must be at least 16 voxels, got {chunk}")
    stack = Path(stack)
    if isinstance(voxel_size, (int, float)) and not (np.isfinite(voxel_size) and voxel_size > 0):
        raise RodwarpError(f"--voxel-size must be a positive number, got {voxel_size:g}")
    vs = parse_voxel_size_text(voxel_size)
    outdir = Path(out) if out is not None else default_out(stack)
    # the folder's owner is checked before the (long) work: a refusal costs nothing and touches nothing
    rundir.check(outdir, "segment", {}, SEGMENT_OUTPUTS, overwrite=overwrite, replace_same_kind=True, inputs=[stack])
    volume = open_volume_lazy(stack)
    source = "--voxel-size"
    if vs is None:
        md = read_voxel_size(stack)
        from rodwarp.ct.io import read_voxel_ratio

        ratio = read_voxel_ratio(stack) if md is None else None
        if ratio is not None and units in (None, "voxel"):
            # a volume with no physical scale (a phantom of a scene): lengths in voxels
            md, units = (ratio, "ImageJ spacing (voxel units)"), "voxel"
        if md is None:
            raise RodwarpError(f"{stack} records no voxel size (no ImageJ/OME spacing metadata); pass --voxel-size "
                               f"(one value, or three for z,y,x) and --units")
        sizes_m, source = md
        if units is None:
            from rodwarp.ct.io import read_voxel_unit

            # the unit the file states its voxel in (phantom writes the rods' own), else by size
            units = read_voxel_unit(stack) or ("mm" if min(sizes_m) >= 1e-4 else "um")
        if units == "voxel":
            vs = tuple(v / min(sizes_m) for v in sizes_m)
        else:
            vs = tuple(v / UNITS[units] for v in sizes_m)
    units = units or "mm"
    if units == "voxel" and source == "--voxel-size" and not np.allclose(vs, 1.0):
        raise RodwarpError("with --units voxel the voxel size is 1 by definition; drop --voxel-size or pick m, mm, um")
    p = params or SegmentParams()
    h = min(vs)
    p = replace(p, diameter=None if diameter is None else diameter / h, chunk=chunk,
                contact_tolerance=contact_tolerance)
    with progress_bar(progress) as update:
        result = segment_volume(volume, p, progress=update, voxel_size=vs)
    summary = {
        "input": str(stack),
        "shape_zyx": list(volume.shape),
        "dtype": str(volume.dtype),
        # two grey levels: segmented from the mask (quality["binarised"] holds the levels)
        "binarised": result.quality.get("binarised") is not None,
        "voxel_size_zyx": list(vs),
        "voxel_size_source": source,
        "parameters": asdict(p),
        "rodwarp_version": versions()["rodwarp"],
        "versions": versions("skimage", "tifffile"),
        "out": str(outdir),
    }
    spacing = result.spacing if units != "voxel" else 1.0
    grid = (h / vs[2], h / vs[1], h / vs[0])
    # taken only now, with the results in hand: an earlier segmentation stays whole until then,
    # and a kill while the outputs are written leaves this folder marked incomplete
    run = rundir.claim(outdir, "segment", {"input": str(stack.resolve()), "voxel_size_zyx": list(vs), "units": units,
                                           "voxel_size_source": source, **asdict(p)},
                       SEGMENT_OUTPUTS, overwrite=overwrite, replace_same_kind=True, inputs=[stack])
    from rodwarp._util import slow_phase

    with slow_phase("writing the rods, contacts and QA figures", enabled=progress):  # the figures take seconds
        s = write_outputs(outdir, result, volume, voxel_size=spacing, units=units, summary=summary, figures=figures,
                          grid_scale=grid)
    s["wall_time_s"] = time.perf_counter() - t0
    write_json(outdir / "summary.json", s)
    run.complete()
    return s


__all__ = ["run_segment", "parse_voxel_size_text", "default_out", "to_physical", "write_rods_csv",
           "write_contacts_csv", "write_filaments_csv", "plot_qa_slices", "plot_qa_projection",
           "plot_qa_confidence", "write_outputs"]
