"""Gauss-Seidel colouring (the race-free GPU path) and CPU/CUDA agreement.

CPU and CUDA run the same kernels in float64; with colouring switched on on both devices
the contacts are visited in the same order, so results agree to round-off (tolerances below).
"""

import numpy as np
import pytest

from rodwarp.experiments import random_packing
from rodwarp.sim import STEEL, Model, ModelBuilder, State
from rodwarp.sim.model import Material
from rodwarp.sim.solver import RodSolver, run
from rodwarp.testing.scenes import TEST_DENSITY, TEST_YOUNG, cantilever


def small_pile(device, coloring, steps=60, seed=3):
    rods = random_packing(40, 1.0, 0.02, (0.6, 0.6, 1.2), seed=seed, device="cpu")
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -9.81), device=device)
    builder.add_box((0, 0, 0), (0.6, 0.6, 1.2), walls=("floor", "x-", "x+", "y-", "y+"))
    model = builder.finalize()
    solver = RodSolver(model, iterations=20, tolerance=0.0, coloring=coloring)
    a = model.state()
    b = State(model)
    points = solver.contacts()
    dt = solver.default_dt()
    colors = []
    for _ in range(steps):
        solver.collide(a, None, dt, points)
        info = solver.step(a, b, None, points, dt)
        a, b = b, a
        if solver.coloring and info.n_contacts:
            colors.append(solver.colors_used)
            check_coloring(model, points, solver)
    return model, a, colors


def check_coloring(model, points, solver):
    n = points.count
    seg = points.last.seg.numpy()[:n]
    ids = solver.collision.color_ids.numpy()
    for c0, c1 in solver.collision.color_ranges:
        members = ids[c0:c1]
        va = model.seg_vertex_np[seg[members, 0]]
        vb = model.seg_vertex_np[seg[members, 1]]
        verts = np.concatenate([va, va + 1, vb, vb + 1])
        assert len(np.unique(verts)) == len(verts), "two contacts of one colour share a vertex"
    covered = np.sort(np.concatenate([ids[c0:c1] for c0, c1 in solver.collision.color_ranges]))
    assert np.array_equal(covered, np.arange(n))


def test_coloring_is_valid_and_close_to_sequential_gauss_seidel():
    m1, s1, colors = small_pile("cpu", "on")
    assert colors and max(colors) >= 2
    m0, s0, _ = small_pile("cpu", "off")
    # a different visiting order converges to nearly the same step (contact-rich, 60 steps)
    assert np.max(np.abs(s1.positions() - s0.positions())) < 1e-3


@pytest.mark.cuda
def test_cantilever_cpu_and_cuda_agree():
    tips = []
    for dev in ("cpu", "cuda"):
        rods, pinned = cantilever(9)
        model = Model(rods, Material(TEST_YOUNG, TEST_DENSITY), gravity=(0, 0, -9.81), damping=40.0,
                      pinned=pinned, rod_contacts=False, device=dev)
        state = run(RodSolver(model, iterations=4, tolerance=0.0), model.state(), 0.5, 1e-3)
        tips.append(state.positions()[-1])
    assert np.max(np.abs(tips[0] - tips[1])) < 1e-12


@pytest.mark.cuda
def test_pile_cpu_and_cuda_agree_with_coloring():
    _, s_cpu, _ = small_pile("cpu", "on")
    _, s_gpu, _ = small_pile("cuda", "on")
    assert np.max(np.abs(s_cpu.positions() - s_gpu.positions())) < 1e-9


KERNEL_MODULES = ("frames", "elastics", "friction", "overlap", "narrowphase", "broadphase", "solve", "fields", "acn",
                  "packing")


@pytest.mark.parametrize("name", KERNEL_MODULES)
def test_kernels_compile_for_cuda_without_a_gpu(name):
    """Every kernel module also compiles for a GPU (sm_90, through NVRTC): the CUDA code path is
    checked on machines without one. Skips where Warp ships no NVRTC."""
    import importlib
    import os

    import warp as wp

    from rodwarp import _warp

    _warp.init()
    if 90 not in (wp.get_cuda_supported_archs() or []):
        pytest.skip("this Warp build cannot compile for sm_90 (no NVRTC)")
    mod = importlib.import_module(f"rodwarp.kernels.{name}")
    out = os.path.join(_warp.kernel_cache_dir(), "aot_sm90")
    wp.compile_aot_module(mod, arch=90, module_dir=out, use_ptx=True)
    assert any(f.endswith(".ptx") for f in os.listdir(out))
