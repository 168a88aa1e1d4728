"""Contact laws are one tagged kind: a new law is a host module, a device module and a line in
the registry (rodwarp/sim/contact_law.py).

The toy law below, frictionless Signorini contact, is written as those two modules in a
temporary folder (its class registered by the ``register_contact_law`` decorator, as the
built-in laws' are) and imported by the scene (what the registry's line does for a built-in
law); a rod lying across an incline then slides down it at exactly g sin(theta), where the
exact law with the same friction coefficient holds it still. The toy law runs in a fresh
process: the kernels that dispatch over the laws are built once there (two modules compile
once per Warp cache) and the laws of this test process stay as they are.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap

import pytest

from rodwarp.errors import RodwarpError
from rodwarp.sim import ContactLaw
from rodwarp.sim.contact_law import CONTACT_LAWS, register_contact_law
from rodwarp.sim.law_exact import ExactLaw
from rodwarp.sim.law_imc import ImcLaw

#: the device module of the toy law: the four functions of kernels/contact_laws.py's interface
TOY_DEVICE = '''
import warp as wp

from rodwarp.kernels.constants import F0
from rodwarp.kernels.structs import LawParams


@wp.func
def settings():
    return 2, wp.float64(1.0e-9), 1


@wp.func
def closed_form(uf: wp.vec3d, n: wp.vec3d, target: wp.float64, Winv: wp.mat33d, mu: wp.float64, lp: LawParams):
    return 0, wp.vec3d(F0, F0, F0), F0


@wp.func
def normal_impulse(gap: wp.float64, target: wp.float64, cn: wp.float64, wnn: wp.float64, pn: wp.float64,
                   dt: wp.float64, lp: LawParams):
    return wp.max(F0, (target - cn) / wnn)


@wp.func
def friction_impulse(c1: wp.float64, c2: wp.float64, w11: wp.float64, w12: wp.float64, w22: wp.float64,
                     limit: wp.float64, guess: wp.float64, lp: LawParams):
    return wp.vec3d(F0, F0, F0)
'''

#: the host module of the toy law: its class (no parameters)
TOY_HOST = '''
from dataclasses import dataclass

import toy_kernels
from rodwarp.sim.contact_law import ContactLaw, register_contact_law


@register_contact_law
@dataclass(frozen=True)
class FrictionlessLaw(ContactLaw):
    """Signorini without friction."""

    name = "frictionless"
    device = toy_kernels
'''

#: the scene: one rigid rod across an incline of 30 degrees (gravity tilted on a flat floor),
#: its spin locked, friction 0.8 (above tan 30 = 0.58: the exact law holds it)
SCENE = '''
import json, sys
import numpy as np
import toy_law  # noqa: F401 (the registry's line for this law; rodwarp/sim/contact_law.py imports the built-in ones)
from rodwarp.rodset import RodSet
from rodwarp.sim import STEEL, ContactLaw, ModelBuilder, RodSolver, run
from rodwarp.testing.scenes import straight_rod, tilted_gravity
R, DT, STEPS = 0.01, 1e-3, 100
out = {}
for law in ("frictionless", "exact"):
    rods = RodSet.from_polylines([straight_rod((0.0, 0.0, R), (0, 1, 0), 0.5, R)], R)
    builder = ModelBuilder(rods, STEEL, gravity=tilted_gravity(9.81, 30.0), mu=0.8, rod_contacts=False,
                           rod_model="rigid", rolling=False, contact_law=ContactLaw(law))
    builder.add_plane((0, 0, 1), 0.0, name="floor")
    model = builder.finalize()
    state = run(RodSolver(model), model.state(), STEPS * DT, DT)
    out[law] = {"v": state.v.numpy().mean(axis=0).tolist(), "x": state.x.numpy().mean(axis=0).tolist(),
                "name": model.contact_law.name, "tag": model.contact_law.tag}
json.dump(out, sys.stdout)
'''


def test_a_toy_law_in_two_modules_and_one_registration_slides_a_rod_at_g_sin_theta(tmp_path):
    (tmp_path / "toy_kernels.py").write_text(textwrap.dedent(TOY_DEVICE))
    (tmp_path / "toy_law.py").write_text(textwrap.dedent(TOY_HOST))
    (tmp_path / "scene.py").write_text(textwrap.dedent(SCENE))
    res = subprocess.run([sys.executable, str(tmp_path / "scene.py")], cwd=tmp_path, capture_output=True, text=True,
                         env={**__import__("os").environ, "PYTHONPATH": str(tmp_path)}, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    toy, exact = out["frictionless"], out["exact"]
    assert toy["name"] == "frictionless" and toy["tag"] == len(CONTACT_LAWS)  # after exact and imc
    g_sin = 9.81 * math.sin(math.radians(30.0))
    t = 100 * 1e-3
    # implicit Euler on a frictionless incline: v_n = n dt g sin(theta), x_n = x_0 + dt^2 g sin(theta) n (n + 1) / 2
    assert toy["v"][0] == pytest.approx(g_sin * t, rel=1e-9)
    assert toy["x"][0] == pytest.approx(g_sin * 1e-6 * 100 * 101 / 2, rel=1e-9)
    assert abs(toy["v"][2]) < 1e-9 and abs(toy["x"][2] - 0.01) < 1e-6  # it stays on the floor
    assert abs(exact["v"][0]) < 1e-6  # the exact law with mu 0.8 holds it


def test_the_registry_names_builds_and_refuses_laws():
    assert list(CONTACT_LAWS)[:2] == ["exact", "imc"]
    assert isinstance(ContactLaw("imc", nu=0.01), ImcLaw)  # the name spelling builds the law's class
    assert ContactLaw.from_tag("exact") == ExactLaw()
    assert (ExactLaw().tag, ImcLaw().tag) == (0, 1)
    assert ImcLaw(delta=1e-3, nu=0.01, stiffness=2.0).device_params() == (2.0, 15e3, 1.5e3, 1e-3, 0.01)
    assert ImcLaw.parameters() == {"delta": None, "nu": 1e-3, "stiffness": None} and ExactLaw.parameters() == {"restitution": 0.0}
    with pytest.raises(RodwarpError, match="exact or imc"):
        ContactLaw("hertz")
    with pytest.raises(TypeError):
        ContactLaw("exact", nu=0.01)  # the exact law's one parameter is restitution
    with pytest.raises(RodwarpError, match="already registered"):

        class Other(ExactLaw):
            pass

        register_contact_law(Other)
