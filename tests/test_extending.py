"""Extending rodwarp in the number of files docs/extending.md states: a protocol (one module and
one registration), a simulate option (one dataclass field), and the run plan's pieces.

The other extension points have their own tests: a contact law (tests/test_contact_law_registry.py),
a segmentation stage (tests/test_segment_stages.py), a wall kind (tests/test_cone_wall.py), an
analyze field (tests/test_registry.py).
"""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest

from rodwarp.errors import RodwarpError
from rodwarp.experiments import PROTOCOLS, Protocol, ProtocolParams, Stage, register_protocol, run_protocol


class DropProtocol(Protocol):
    """A toy protocol, all in this class: the paper's random packing dropped on a bare floor
    (no container), left to settle; the settling is the test. summary.json gains ``drop``."""

    name = "drop"
    help = "rods dropped on a bare floor"

    def rods(self, params):
        return PROTOCOLS["paper"].rods(params)

    def packing(self, params, device):
        return PROTOCOLS["paper"].packing(params, device)

    def walls(self, builder, params, rods):
        from rodwarp.sim.walls import Plane

        builder.add_wall(Plane.make((0.0, 0.0, 1.0), 0.0, name="floor"))
        lo, hi = rods.bounding_box()
        return lo, hi

    def plan(self, params):
        return (Stage("settle", params.duration, test=True, title="settling", option="--duration"),)

    def columns(self, model, x, control, t):
        return {"lowest_z": float(np.min(x[:, 2] - model.radius_np[model.vertex_rod_np]))}

    def summary(self, params, model, rows, loop, stages, thresholds):
        return "drop", {"lowest_z_m": rows[-1]["lowest_z"], "stages": [s.name for s in stages]}


def test_a_toy_protocol_is_one_class_and_one_registration(tmp_path):
    proto = register_protocol(DropProtocol())
    try:
        params = ProtocolParams(protocol="drop", alpha=20, n_rods=8, length=0.05, gravity=9.81, duration=0.5,
                                save_every=0.05, fields_every=0.0, device="cpu")
        s = run_protocol(params, tmp_path / "run", progress=False)
        with open(tmp_path / "run" / "metrics.csv") as fh:
            rows = list(csv.DictReader(fh))
        # its stage, its column and its summary block went through the common loop and outputs
        assert {r["stage"] for r in rows} == {"settle"} and s["drop"]["stages"] == ["settle"]
        d = params.diameter
        # the known answer: dropped from up to 2.5 l, the rods have landed on the floor and rest
        # there (the lowest surface point on it within the solver's overlap tolerance)
        z0 = float(rows[0]["lowest_z"])
        assert z0 > 0.5 * d  # they started in the air
        assert abs(s["drop"]["lowest_z_m"]) < 0.05 * d
        # and the pile came down onto it: its mass centroid fell from mid-box to a few diameters
        assert float(rows[-1]["centroid_height"]) < 0.25 * float(rows[0]["centroid_height"])
        # options of other protocols are refused with it, as with any protocol
        with pytest.raises(RodwarpError, match="--strains does not apply with --protocol drop"):
            dataclasses.replace(params, strains=(0.1,)).validate()
    finally:
        del PROTOCOLS[proto.name]


def test_a_protocol_with_unknown_fields_or_own_parameters_is_refused():
    class Bad(DropProtocol):
        name = "bad"
        fields = ("no_such_option",)

    with pytest.raises(RodwarpError, match="no_such_option"):
        register_protocol(Bad())
    assert "bad" not in PROTOCOLS


def test_every_parameter_is_an_option_of_simulate_in_its_dataclass_order():
    """A new parameter is one field: the command's options are generated from the dataclasses."""
    from typer.main import get_command

    from rodwarp.cli import app

    cmd = get_command(app).commands["simulate"]
    names = [p.name for p in cmd.params]
    fields = [f.name for f in dataclasses.fields(ProtocolParams)]
    assert names[:len(fields)] == fields
    assert names[len(fields):] == ["resume", "overwrite", "out", "entangled_from", "quiet"]
    # each protocol's own fields come from its Params dataclass, and --protocol lists the registry
    for proto in PROTOCOLS.values():
        if proto.Params is not None:
            assert {f.name for f in dataclasses.fields(proto.Params)} <= set(fields)
    help_text = next(f for f in dataclasses.fields(ProtocolParams) if f.name == "protocol").metadata["help"]
    assert all(f"{name} (" in help_text for name in PROTOCOLS)


def test_the_loop_names_no_protocol_and_no_stage():
    """The stepping loop reads stages only through their pieces (docs/extending.md)."""
    import inspect

    from rodwarp.experiments import _loop

    src = inspect.getsource(_loop)
    for word in ("paper", "lab", "excitation", "entangle", "stability", "pour", "press", "shake", "piston"):
        assert f'"{word}' not in src and f"'{word}" not in src, word
    assert "protocols" not in src
