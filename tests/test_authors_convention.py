"""``--convention text|authors``: both conventions against brute-force NumPy/Python oracles written
here (a different code path: loops, the four-arcsin form of the Gauss integral), the factor ~2 of
the authors' e, and the CLI."""

import json
import math

import numpy as np
import pytest

from rodwarp.analysis import compute_fields
from rodwarp.analysis._authors import entanglement_e2, phi_from_image
from rodwarp.errors import RodwarpError
from rodwarp.rodset import Contacts, RodSet


# ---------------------------------------------------------------- oracles (loops, arcsin form)

def _unit(v):
    n = math.sqrt(sum(c * c for c in v))
    return None if n == 0 else [c / n for c in v]


def _sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def acn(p1, p2, p3, p4):
    """|G| of segments p1-p2 and p3-p4 (Klenin & Langowski's four-arcsin form); 0 when degenerate."""
    r13, r14, r23, r24 = _sub(p3, p1), _sub(p4, p1), _sub(p3, p2), _sub(p4, p2)
    ns = [_unit(_cross(r13, r14)), _unit(_cross(r14, r24)), _unit(_cross(r24, r23)), _unit(_cross(r23, r13))]
    if any(n is None for n in ns):
        return 0.0
    om = sum(math.asin(max(-1.0, min(1.0, _dot(ns[i], ns[(i + 1) % 4])))) for i in range(4))
    return abs(om) / (4 * math.pi)


def edges_of(polys):
    out = []
    for r, p in enumerate(polys):
        for i in range(len(p) - 1):
            out.append((list(map(float, p[i])), list(map(float, p[i + 1])), r))
    return out


def authors_oracle(polys, contact_pts, centre, R, norm):
    """The authors' rules at one centre, by loops."""
    kept = [e for e in edges_of(polys) if math.dist(e[0], centre) < R]
    labels = sorted({e[2] for e in kept})
    n = len(labels)
    e = sum(acn(a[0], a[1], b[0], b[1]) for a in kept for b in kept if a[2] != b[2])
    first = kept[:n]
    e2 = 0.0
    for i, a in enumerate(first):
        for j, b in enumerate(first):
            if i != j:
                shares = any(u == v for u in (a[0], a[1]) for v in (b[0], b[1]))
                e2 += 0.5 if shares else acn(a[0], a[1], b[0], b[1])
    if kept:
        Q = np.zeros((3, 3))
        for a in kept:
            u = np.array(_unit(_sub(a[0], a[1])))
            Q += np.outer(u, u)
        w, _ = np.linalg.eig((3 * Q / len(kept) - np.eye(3)) / 2)
        S = float(np.real(w[np.argmax(np.abs(w))]))
    else:
        S = 0.0
    k = sum(1 for p in contact_pts if math.dist(p, centre) < R)
    return {"n": n, "e": e, "e2": e2, "S": S, "contacts": k, "c": k / norm}


def clip(p, q, c, R):
    """The part of segment p-q inside the ball (c, R), or None."""
    d, f = np.subtract(q, p), np.subtract(p, c)
    a, b, cc = d @ d, 2 * f @ d, f @ f - R * R
    disc = b * b - 4 * a * cc
    if disc <= 0:
        return None
    t0, t1 = max(0.0, (-b - math.sqrt(disc)) / (2 * a)), min(1.0, (-b + math.sqrt(disc)) / (2 * a))
    if t1 <= t0:
        return None
    return list(np.add(p, t0 * d)), list(np.add(p, t1 * d))


def text_oracle(polys, centre, R, d):
    """The text's rules at one centre, by loops: exact clipping, each rod pair once."""
    parts = []
    for a, b, r in edges_of(polys):
        c = clip(a, b, centre, R)
        if c is not None:
            parts.append((c[0], c[1], r))
    n = len({p[2] for p in parts})
    e = sum(acn(parts[i][0], parts[i][1], parts[j][0], parts[j][1])
            for i in range(len(parts)) for j in range(i + 1, len(parts)) if parts[i][2] != parts[j][2])
    L = [math.dist(p[0], p[1]) for p in parts]
    phi = sum(L) * math.pi * d * d / 4 / (4 / 3 * math.pi * R**3)
    return {"n": n, "e": e, "phi": phi}


# ---------------------------------------------------------------- a small packing

def _packing(n_rods=7, n_edges=6, box=4.0, seed=3):
    rng = np.random.default_rng(seed)
    polys = []
    for _ in range(n_rods):
        c, u = rng.uniform(0.5, box - 0.5, 3), rng.normal(size=3)
        u /= np.linalg.norm(u)
        t = np.linspace(-1.6, 1.6, n_edges + 1)[:, None]
        bend = 0.15 * np.sin(np.linspace(0, np.pi, n_edges + 1))[:, None] * rng.normal(size=3)
        polys.append(c + t * u + bend)
    pts = rng.uniform(0, box, (9, 3))
    pairs = [(0, j) for j in range(1, 7)] + [(1, 2), (1, 3), (2, 3)]
    contacts = Contacts(rod_i=np.array([p[0] for p in pairs]), rod_j=np.array([p[1] for p in pairs]), point=pts,
                        gap=np.zeros(9))
    return polys, pts, contacts


def _norm(polys, K, R):
    v = np.concatenate([np.asarray(p) for p in polys])
    # the authors' cylinder: height max z from 0, diameter the mean of the x and y extents
    D = ((v[:, 0].max() - v[:, 0].min()) + (v[:, 1].max() - v[:, 1].min())) / 2
    return K * (4 / 3 * math.pi * R**3) / (math.pi * D * D * v[:, 2].max() / 4)


R, H, BOX = 1.5, 1.0, [[0, 0, 0], [4.0, 4.0, 4.0]]


def test_authors_convention_against_brute_force():
    polys, pts, contacts = _packing()
    rods = RodSet.from_polylines(polys, radii=0.05)
    f = compute_fields(rods, radius=R, spacing=H, domain=BOX, contacts=contacts, convention="authors")
    # the authors' grid: R, R + h, ... up to extent - R
    np.testing.assert_allclose(f.x, [1.5, 2.5], atol=1e-12)
    np.testing.assert_allclose(f.z, [1.5, 2.5], atol=1e-12)
    assert f.attrs["convention"] == "authors" and np.isnan(f.phi).all()
    norm = _norm(polys, len(pts), R)
    assert f.attrs["c_normalisation"] == pytest.approx(norm, rel=1e-12)
    from rodwarp.analysis._authors import authors_field_arrays

    p0, p1, rid = rods.segments()
    arr = authors_field_arrays(p0, p1, rid, pts, f.x, f.y, f.z, R)
    checked = 0
    for iz, z in enumerate(f.z):
        for iy, y in enumerate(f.y):
            for ix, x in enumerate(f.x):
                ref = authors_oracle(polys, pts, [x, y, z], R, norm)
                got = {k: getattr(f, k)[iz, iy, ix] for k in ("n", "e", "S", "contacts", "c")}
                got["e2"] = arr["e2"][iz, iy, ix]
                for k, v in ref.items():
                    assert got[k] == pytest.approx(v, abs=1e-6), (k, x, y, z)
                checked += ref["n"] > 1 and ref["e"] > 0
    assert checked >= 4  # the packing is tangled enough to test e


def test_text_convention_against_brute_force():
    polys, pts, contacts = _packing(seed=5)
    rods = RodSet.from_polylines(polys, radii=0.05)
    f = compute_fields(rods, radius=R, spacing=H, domain=BOX, contacts=contacts, keep_outside=True)  # text: default
    assert f.attrs["convention"] == "text"
    checked = 0
    for iz, z in enumerate(f.z):
        for iy, y in enumerate(f.y):
            for ix, x in enumerate(f.x):
                if not np.isfinite(f.e[iz, iy, ix]):
                    continue
                ref = text_oracle(polys, [x, y, z], R, 0.1)
                for k, v in ref.items():
                    assert getattr(f, k)[iz, iy, ix] == pytest.approx(v, abs=1e-6), (k, x, y, z)
                checked += ref["e"] > 0
    assert checked >= 4


def test_e2_counts_the_first_n_edges_and_shared_vertices():
    # one rod of 3 edges and one of 1: n = 2, so e2 pairs the first two kept edges, which are
    # consecutive edges of rod 0 sharing a vertex: 1/2 each way
    a = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1], [5, 5, 5]], float)
    b = np.array([[1, 0, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1], [5, 5, 6]], float)
    assert entanglement_e2(a[[0, 1, 2, 4]], b[[0, 1, 2, 4]], 2) == pytest.approx(1.0)
    assert entanglement_e2(a[:1], b[:1], 1) == 0.0


def test_phi_from_image_digital_sphere():
    # the mask holds offsets -R+1 .. R+1, x^2 + y^2 + z^2 < R^2: the sphere sits one voxel low
    R = 3
    img = np.zeros((9, 9, 9), bool)
    img[:4] = True  # x index 0..3
    c = (4, 4, 4)
    ref, total = 0, 0
    for i in range(-R + 1, R + 2):
        for j in range(-R + 1, R + 2):
            for k in range(-R + 1, R + 2):
                if i * i + j * j + k * k < R * R:
                    total += 1
                    ref += img[c[0] + i - 1, c[1] + j - 1, c[2] + k - 1]
    assert phi_from_image(img, c, R) == pytest.approx(ref / total, abs=1e-12)
    assert 0 < ref < total


def test_authors_e_is_about_twice_the_text_e_on_finely_divided_rods():
    # straight isotropic rods, alpha = l / d = 100, R = sqrt(d l) = 10 d, edges of 1 d (cheap case)
    d, l, Rb, box = 1.0, 100.0, 10.0, 60.0
    rng = np.random.default_rng(0)
    N = 120
    C, U = rng.uniform(0, box, (N, 3)), rng.normal(size=(N, 3))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    t = np.linspace(-l / 2, l / 2, 101)[None, :, None]
    rods = RodSet.from_polylines(list(C[:, None] + t * U[:, None]), radii=d / 2)
    kw = dict(radius=Rb, spacing=Rb, domain=[[0, 0, 0], [box] * 3], contacts=Contacts.empty())
    fa = compute_fields(rods, convention="authors", **kw)
    ft = compute_fields(rods, **kw)
    # with spacing R and an extent of 2 R + k R the text grid's valid voxels are the authors' centres
    et = ft.e[np.isfinite(ft.e)]
    assert et.size == fa.e.size
    ratio = fa.e.sum() / et.sum()
    assert 1.9 < ratio < 2.01, ratio


def test_cli_convention_authors(tmp_path):
    from typer.testing import CliRunner

    from rodwarp.analysis import Fields
    from rodwarp.cli import app

    polys, pts, contacts = _packing(seed=11)
    rods = RodSet.from_polylines(polys, radii=0.05, units="m")
    rods.contacts = contacts
    rods.box = np.array(BOX, float)
    src = tmp_path / "rods.npz"
    rods.save(src)
    out = tmp_path / "an"
    res = CliRunner().invoke(app, ["analyze", str(src), "--out", str(out), "--radius", str(R), "--spacing", str(H),
                                   "--convention", "authors", "--no-figures", "--quiet"])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["convention"] == "authors" and summary["options"]["convention"] == "authors"
    f = Fields.load(out / "fields.zarr")
    norm = _norm(polys, len(pts), R)
    for iz, z in enumerate(f.z):
        for iy, y in enumerate(f.y):
            for ix, x in enumerate(f.x):
                ref = authors_oracle(polys, pts, [x, y, z], R, norm)
                for k in ("n", "e", "S", "c"):
                    assert getattr(f, k)[iz, iy, ix] == pytest.approx(ref[k], abs=1e-6), (k, x, y, z)
    bad = CliRunner().invoke(app, ["analyze", str(src), "--out", str(tmp_path / "b"), "--convention", "matlab"])
    assert bad.exit_code != 0 and "--convention must be text" in bad.output


def test_convention_checked():
    polys, _, _ = _packing()
    rods = RodSet.from_polylines(polys, radii=0.05)
    with pytest.raises(RodwarpError, match="convention"):
        compute_fields(rods, radius=R, spacing=H, domain=BOX, convention="matlab")
