"""Segmentation as a list of stages (rodwarp.ct.segment._stages): a stage added in one file.

The toy stage below is the whole recipe: define the stage, insert it into the stage list,
pass the list to segment_volume.  No other file of the package changes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from rodwarp import ct
from rodwarp.ct import DEFAULT_STAGES, SegmentContext, Stage, insert_stage, segment_volume
from rodwarp.errors import RodwarpError


class RodLengths(Stage):
    """Toy stage: the mean rod length (voxels) after refinement, into ``quality``."""

    name = "rod_lengths"
    paths = ("straight",)

    def run(self, ctx: SegmentContext) -> None:
        ctx.extra["mean_length"] = float(np.mean([r.length for r in ctx.rod_list]))

    def quality(self, ctx: SegmentContext) -> dict:
        return {"mean_length_voxels": ctx.extra["mean_length"]}


@pytest.fixture(scope="module")
def volume():
    shape = (48, 56, 64)
    truth = ct.scene_crossing_pair(shape, radius=3.0, angle_deg=90.0, gap=0.0)
    return ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=10.0, seed=0)


def test_default_stage_names():
    assert [s.name for s in DEFAULT_STAGES] == ["prepare", "stats", "detect", "filaments", "merge", "refine",
                                                "contacts", "doubt"]


def test_a_toy_stage_added_in_one_file(volume):
    base = segment_volume(volume)
    stages = insert_stage(DEFAULT_STAGES, RodLengths(), after="refine")
    assert [s.name for s in stages].index("rod_lengths") == [s.name for s in stages].index("refine") + 1
    res = segment_volume(volume, stages=stages)
    # the stage ran, was timed, and reported
    assert "rod_lengths" in res.timings
    lengths = [np.linalg.norm(res.rods.rod(i)[-1] - res.rods.rod(i)[0]) for i in range(res.rods.n_rods)]
    assert res.quality["mean_length_voxels"] == pytest.approx(np.mean(lengths), rel=1e-9)
    # ... and changed nothing else
    np.testing.assert_array_equal(res.rods.points, base.rods.points)
    np.testing.assert_array_equal(res.rods.radii, base.rods.radii)
    rest = {k: v for k, v in res.quality.items() if k != "mean_length_voxels"}
    assert json.dumps(rest, default=str) == json.dumps(base.quality, default=str)  # same keys, order, values
    keys = list(res.quality)
    assert keys.index("mean_length_voxels") > keys.index("rods_rejected")
    assert keys.index("mean_length_voxels") < keys.index("contacts_rejected_by_image")
    assert DEFAULT_STAGES == tuple(s for s in stages if s.name != "rod_lengths")  # the default list is untouched


def test_a_stage_skipped_off_its_path(volume):
    """A curved-only stage is neither run nor asked for its quality on a straight run."""

    class Boom(Stage):
        name = "boom"
        paths = ("curved",)

        def run(self, ctx):
            raise AssertionError("ran off its path")

        def quality(self, ctx):
            raise AssertionError("asked off its path")

    res = segment_volume(volume, stages=insert_stage(DEFAULT_STAGES, Boom(), before="doubt"))
    assert res.rods.n_rods == 2 and "boom" not in res.timings


def test_insert_stage_refuses_unknown_and_taken_names():
    with pytest.raises(RodwarpError, match="no stage named 'nope'"):
        insert_stage(DEFAULT_STAGES, RodLengths(), after="nope")
    with pytest.raises(RodwarpError, match="already in the list"):
        insert_stage(DEFAULT_STAGES, DEFAULT_STAGES[0])
    assert insert_stage(DEFAULT_STAGES, RodLengths())[-1].name == "rod_lengths"
