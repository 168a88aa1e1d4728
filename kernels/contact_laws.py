"""Contact laws as one tagged kind: the device side of the registry.

A contact law is a device module (``kernels/exact.py``, ``kernels/imc.py``) with these
``wp.func`` s, which :func:`rodwarp.kernels.friction.solve_contact` calls for every rod-rod
and rod-wall contact through the dispatchers below:

``closed_form(uf, n, target, Winv, mu, lp) -> (int, vec3d, float64)``
    A case the law settles without iterating: 1 with the impulse (N s) and the friction
    guess for the next sweep, else 0. ``uf``: the contact velocity without its own impulse
    (m/s); ``target``: the lowest normal velocity allowed (m/s); ``Winv``: the inverse
    mobility (N s / m, zero when singular).
``normal_impulse(gap, target, cn, wnn, pn, dt, lp) -> float64``
    The normal impulse (N s) with the tangential part held: ``cn`` the normal velocity
    without it (m/s), ``wnn`` the normal mobility (m / (N s)), ``pn`` the current normal
    impulse (a guess), ``gap`` the surface gap at the start of the step (m).
``friction_impulse(c1, c2, w11, w12, w22, limit, guess, lp) -> vec3d``
    The tangential impulse (p1, p2) (N s) in the contact's tangent basis with the normal part
    held, and the guess kept for the next sweep: ``c`` the tangential velocity without it,
    ``w`` the tangential mobility, ``limit`` = mu p_n.
``settings() -> (int, float64, int)``
    Most alternations of the normal and the tangential part within a contact (where the
    mobility couples them), their relative tolerance, and 1 when an idle contact (no impulse)
    that does not approach faster than its target gets none (the sweep then skips it).

``lp`` is the law's parameter vector (:data:`rodwarp.kernels.structs.LawParams`), packed by
its host module (``device_params``); its layout is the law module's own. The tag of a law
(``StepParams.law``) is its index in :data:`LAWS`, in the order the host registers them
(:mod:`rodwarp.sim.contact_law`; the built-in ``exact`` is 0, ``imc`` 1): the dispatchers
are rebuilt from :data:`LAWS` at each registration, with a branch per law unrolled at
compile time (``wp.static``), so a new law touches no file here.
"""

import warp as wp

from rodwarp.kernels import exact, imc
from rodwarp.kernels.constants import F0
from rodwarp.kernels.structs import LawParams

wp.set_module_options({"enable_backward": False})

#: the device modules of the registered laws; a law's tag is its index. The built-in two are
#: listed here so that kernels launched without the host (tests of a kernel) know them too;
#: the host's registry (rodwarp/sim/contact_law.py) adds any other.
LAWS: list = [exact, imc]
#: set once a solver exists: its kernels are built with the laws registered then
_sealed = [False]


def _dispatchers(laws):
    """The dispatch functions over ``laws`` (each branch calls one law's function)."""
    n_laws = len(laws)

    @wp.func
    def closed_form(law: int, uf: wp.vec3d, n: wp.vec3d, target: wp.float64, Winv: wp.mat33d, mu: wp.float64,
                    lp: LawParams):
        solved = int(0)
        P = wp.vec3d(F0, F0, F0)
        guess = F0
        for k in range(wp.static(n_laws)):
            if law == k:
                solved, P, guess = wp.static(laws[k].closed_form)(uf, n, target, Winv, mu, lp)
        return solved, P, guess

    @wp.func
    def normal_impulse(law: int, gap: wp.float64, target: wp.float64, cn: wp.float64, wnn: wp.float64,
                       pn: wp.float64, dt: wp.float64, lp: LawParams):
        p = F0
        for k in range(wp.static(n_laws)):
            if law == k:
                p = wp.static(laws[k].normal_impulse)(gap, target, cn, wnn, pn, dt, lp)
        return p

    @wp.func
    def friction_impulse(law: int, c1: wp.float64, c2: wp.float64, w11: wp.float64, w12: wp.float64,
                         w22: wp.float64, limit: wp.float64, guess: wp.float64, lp: LawParams):
        q = wp.vec3d(F0, F0, F0)
        for k in range(wp.static(n_laws)):
            if law == k:
                q = wp.static(laws[k].friction_impulse)(c1, c2, w11, w12, w22, limit, guess, lp)
        return q

    @wp.func
    def settings(law: int):
        rounds = int(0)
        tol = F0
        idle = int(0)
        for k in range(wp.static(n_laws)):
            if law == k:
                rounds, tol, idle = wp.static(laws[k].settings)()
        return rounds, tol, idle

    return closed_form, normal_impulse, friction_impulse, settings


closed_form, normal_impulse, friction_impulse, settings = _dispatchers(LAWS)


def register(module) -> int:
    """Add a law's device module (once) and return its tag; rebuilds the dispatchers.

    Raises
    ------
    RuntimeError
        After :func:`seal`: the kernels already built would not see the new law.
    """
    global closed_form, normal_impulse, friction_impulse, settings
    if module in LAWS:
        return LAWS.index(module)
    if _sealed[0]:
        raise RuntimeError(f"contact law {module.__name__} registered after a solver was made: register "
                           "every contact law before the first RodSolver")
    LAWS.append(module)
    closed_form, normal_impulse, friction_impulse, settings = _dispatchers(list(LAWS))
    return len(LAWS) - 1


def seal() -> None:
    """No more registrations (a solver's kernels are about to be built with these laws)."""
    _sealed[0] = True
