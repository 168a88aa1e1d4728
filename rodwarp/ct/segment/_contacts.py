"""Stage ``contacts`` of segmentation: contact candidates from the geometry, confirmed by the image.

The candidates are rod pairs whose surface gap ``|closest axis points| - r_i - r_j`` is below
``contact_tolerance`` (:func:`rodwarp.rodset.detect_contacts`); a candidate becomes a contact
of the packing when the image between the two surfaces is foreground.
"""

from __future__ import annotations

import numpy as np

from rodwarp.ct.segment._levels import _Levels
from rodwarp.ct.segment._params import SegmentParams
from rodwarp.ct.segment._profile import _axis_level
from rodwarp.ct.segment._reader import _Reader
from rodwarp.ct._voxels import _basis, _disc_offsets
from rodwarp.rodset import Contacts, RodSet, detect_contacts, segment_closest_params


def confirm_contacts(rods_out: RodSet, reader: _Reader, st: _Levels, C: float, P: SegmentParams,
                     sigma=None) -> tuple[Contacts, int]:
    """The contacts of the segmented packing: contact candidates the image confirms.

    Parameters
    ----------
    rods_out : RodSet
        The segmented rods (voxel units).
    reader : _Reader
        The prepared volume.
    st : _Levels
        Background and foreground levels.
    C : float
        Fitted contrast of the rods (plateau over fg - bg).
    P : SegmentParams
        ``contact_tolerance`` (voxels) and ``contact_min_fill`` (normalised intensity).
    sigma : float, optional
        Fitted blur (voxels): thin rods and the contacts between them are dimmer under it.

    Returns
    -------
    (Contacts, int)
        The confirmed contacts and the number of candidates the image rejected.
    """
    candidates = detect_contacts(rods_out, tolerance=P.contact_tolerance)
    if len(candidates) == 0:
        return candidates, 0
    cand = candidates
    keep = np.zeros(len(cand), bool)
    scale = 1.0 / ((st.fg - st.bg) * C)
    disc = _disc_offsets(1.0, 0.5)
    for k in range(len(cand)):
        i, j = int(cand.rod_i[k]), int(cand.rod_j[k])
        a0, a1 = rods_out.rod(i)[0], rods_out.rod(i)[-1]
        b0, b1 = rods_out.rod(j)[0], rods_out.rod(j)[-1]
        s, t = segment_closest_params(a0, a1, b0, b1)
        pa = a0 + float(s) * (a1 - a0)
        pb = b0 + float(t) * (b1 - b0)
        d = pb - pa
        dist = float(np.linalg.norm(d))
        if dist < 1e-9:
            keep[k] = True
            continue
        n = d / dist
        ri, rj = rods_out.radii[i], rods_out.radii[j]
        # positions between the two surfaces (at least the midpoint)
        s0, s1 = min(ri, dist - rj), max(ri, dist - rj)
        ss = np.unique(np.concatenate([np.arange(s0, s1 + 1e-9, 0.5), [0.5 * (s0 + s1)]]))
        e1, e2 = _basis(n)
        pts = pa + ss[:, None, None] * n + disc[None, :, 0, None] * e1 + disc[None, :, 1, None] * e2
        val = reader.trilinear(pts.reshape(-1, 3))
        if not np.all(np.isfinite(val)):
            keep[k] = True  # at the border: trust geometry
            continue
        val = (val - st.bg) * scale
        prof = val.reshape(len(ss), len(disc)).mean(1)
        # thin rods are dimmer under blur, and so is the contact between two of them
        lv = 1.0 if sigma is None else min(1.0, _axis_level(min(ri, rj), sigma, min(P.end_radius, max(0.5, 0.8 * min(ri, rj)))))
        keep[k] = bool(prof.min() >= P.contact_min_fill * lv)
    rejected = int((~keep).sum())
    # the candidates the image confirms are the contacts of the packing
    return Contacts(cand.rod_i[keep], cand.rod_j[keep], cand.point[keep], cand.gap[keep]), rejected
