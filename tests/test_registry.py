"""The field registry: one row makes a field appear in fields.zarr, summary.json, the figures and --help.

Two demonstrations: ``n_ends`` (rod ends per ball), shipped as one row of
``rodwarp.analysis.FIELDS`` and checked against a direct count; and a row added here, in the
test alone, which must reach the same four places with no other change.
"""

import importlib
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from rodwarp.analysis import Fields, FieldSpec, _figures, _registry, analyze, compute_fields, field_spec
from rodwarp.experiments import random_packing

runner = CliRunner()


@pytest.fixture(scope="module")
def packing():
    return random_packing(60, 1.0, 1 / 30, (1.0, 1.0, 1.5), seed=5)


@pytest.fixture
def drawn(monkeypatch):
    """Axis labels, titles and colourbar labels of every figure drawn, by file name."""
    seen = {}
    real = _figures.save_figure

    def capture(fig, path, *a, **k):
        texts = []
        for ax in fig.axes:
            texts += [ax.get_xlabel(), ax.get_ylabel(), ax.get_title()]
        seen[str(path).rsplit("/", 1)[-1]] = texts
        return real(fig, path, *a, **k)

    monkeypatch.setattr(_figures, "save_figure", capture)
    return seen


def _help_text() -> str:
    import rodwarp.cli

    cli = importlib.reload(rodwarp.cli)  # the help is built from the registry when the CLI loads
    res = runner.invoke(cli.app, ["analyze", "--help"], terminal_width=400)
    assert res.exit_code == 0, res.output
    return " ".join(res.output.split())


def _appears_everywhere(name: str, out, drawn):
    import zarr

    spec = field_spec(name)
    g = zarr.open_group(str(out / "fields.zarr"), mode="r")
    assert name in g and g[name].shape == g["e"].shape  # fields.zarr
    s = json.loads((out / "summary.json").read_text())
    assert spec.summary in s and s[spec.summary] is not None  # summary.json: its mean ...
    assert s["histograms"][name] is not None and name in s["z_profiles"]  # ... histogram, z-profile
    for png in ("histograms.png", "slices.png", "zprofiles.png"):  # a panel in each figure
        assert (out / png).exists()
        assert any(spec.symbol in t for t in drawn[png]), (png, drawn[png])
    assert f"{name}: {spec.title}" in _help_text()  # rodwarp analyze --help
    return g, s


def test_n_ends_is_one_row_and_counts_rod_ends(packing, tmp_path, drawn):
    src = tmp_path / "rods.npz"
    packing.save(src)
    out = tmp_path / "an"
    analyze(src, out)
    g, s = _appears_everywhere("n_ends", out, drawn)
    # against a direct count: rod ends within R of each voxel centre
    f = Fields.load(out / "fields.zarr")
    ends = np.concatenate([packing.points[packing.offsets[:-1]], packing.points[packing.offsets[1:] - 1]])
    zz, yy, xx = np.meshgrid(f.z, f.y, f.x, indexing="ij")
    centres = np.stack([xx, yy, zz], -1).reshape(-1, 3)
    d = np.linalg.norm(centres[:, None, :] - ends[None, :, :], axis=-1)
    direct = (d <= f.radius).sum(1).reshape(f.shape).astype(float)
    ok = np.isfinite(f.n_ends)
    assert ok.any()
    np.testing.assert_array_equal(f.n_ends[ok], direct[ok])
    assert s["mean_n_ends"] == pytest.approx(float(np.mean(f.n_ends[f.valid])))


def test_a_row_alone_adds_a_field(packing, tmp_path, monkeypatch, drawn):
    # the mean clipped length per rod in the ball: a new field from the existing measures
    row = FieldSpec("mean_clip", lambda b: np.where(b.rods > 0, b.length / np.maximum(b.rods, 1), np.nan),
                    "length", "mean", ("histogram", "slices", "zprofile"), "mean_mean_clip",
                    r"$\bar{L}$", "clipped length per rod", "sum of clipped lengths / rods in the ball")
    monkeypatch.setattr(_registry, "FIELDS", _registry.FIELDS + (row,))
    try:
        f = compute_fields(packing)
        expect = np.where(f.n > 0, f.phi * (4 / 3 * np.pi * f.radius**3) / (np.pi / 4 * (2 * packing.radii[0]) ** 2)
                          / np.maximum(f.n, 1), np.nan)
        np.testing.assert_allclose(f.mean_clip, expect, rtol=1e-12, equal_nan=True)
        src = tmp_path / "rods.npz"
        packing.save(src)
        out = tmp_path / "an"
        analyze(src, out)
        _appears_everywhere("mean_clip", out, drawn)
    finally:
        monkeypatch.undo()
        _help_text()  # the CLI again as shipped


def test_registry_rows_are_checked():
    with pytest.raises(ValueError, match="reducer"):
        FieldSpec("x2", lambda b: b.rods, "1", "median", (), "median_x2", "$x$", "x", "x")
    with pytest.raises(ValueError, match="panels"):
        FieldSpec("x2", lambda b: b.rods, "1", None, ("pie",), None, "$x$", "x", "x")
    with pytest.raises(ValueError, match="identifier"):
        FieldSpec("z", lambda b: b.rods, "1", None, (), None, "$z$", "z", "z")
