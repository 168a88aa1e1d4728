"""The stability verdict of the vibration test: height kept, persistence and the contact cluster.

A packing passes the paper's stability test when it *stays a pile*: it keeps its height
above the floor and holds together in one contact cluster for most of the test. Three
series, sampled every ``save_every`` seconds of the test, carry the verdict:

* height kept h(t) = y_c(t) / y_c(t_0): the mass centroid's height above the floor over
  its value when the test starts (the seed paper's Fig. 1E, normalised centroid height);
* f(t): rods in the largest contact cluster over all rods (the paper's Fig. 4H measure);
* rods left r(t): the fraction of rods that have left the pile (:func:`rods_left`).

The packing counts as *entangled* at a sample when h >= ``height_kept`` and f >=
``cluster``. The persistence tau is the fraction of the test time during which it is
entangled (the paper's Fig. 1F, tau = t_entangled / T). The verdict (:func:`judge`):

    stable  <=>  entangled at the last sample  and  tau >= ``persistence``.

A pile that spreads into a mat on the floor while its rods still touch fails on h; one that
holds, then collapses midway has tau near 1/2; one that breaks into loose rods fails on f.
The thresholds are set from measurement (``benchmarks/bench_verdict.py``, ``docs/verdict.md``):
they sit where the measured runs separate into two groups. The experiment they judge is
``docs/protocol.md``.

Everything here is plain NumPy on metric series, so a finished run can be judged again with
other thresholds from its ``metrics.csv`` (:func:`judge_metrics_csv`).
"""

from __future__ import annotations

import csv
import math
from dataclasses import asdict, dataclass

import numpy as np

from rodwarp.errors import RodwarpError


@dataclass(frozen=True)
class Thresholds:
    """Thresholds of the stability verdict (dimensionless).

    Parameters
    ----------
    height_kept : float
        Smallest height kept h = y_c(t) / y_c(t_0) of an entangled packing.
    cluster : float
        Smallest largest-cluster fraction f of an entangled packing.
    persistence : float
        Smallest persistence tau (fraction of the test spent entangled) of a stable packing.
    """

    # midpoints of the measured gaps (benchmarks/bench_verdict.py, docs/verdict.md "Measured")
    height_kept: float = 0.26
    cluster: float = 0.8
    persistence: float = 0.63

    def __post_init__(self):
        for name, v in asdict(self).items():
            if not (0.0 <= v <= 1.0 and math.isfinite(v)):
                raise RodwarpError(f"verdict threshold '{name}' must lie in [0, 1], got {v!r}")

    def to_dict(self) -> dict:
        return asdict(self)


DEFAULT_THRESHOLDS = Thresholds()

RULE = ("stable = (height_kept >= {height_kept:g} and largest_cluster_fraction >= {cluster:g} at the end of the "
        "test) and persistence >= {persistence:g}; persistence = fraction of the test time with height_kept >= "
        "{height_kept:g} and largest_cluster_fraction >= {cluster:g}")


@dataclass
class Verdict:
    """Outcome of :func:`judge` (all fractions dimensionless)."""

    stable: bool
    height_kept: float
    persistence: float
    largest_cluster_fraction: float
    rods_left: float | None
    thresholds: Thresholds

    def to_dict(self) -> dict:
        return {"stable": bool(self.stable), "height_kept": float(self.height_kept),
                "persistence": float(self.persistence),
                "largest_cluster_fraction": float(self.largest_cluster_fraction),
                "rods_left": None if self.rods_left is None else float(self.rods_left),
                "thresholds": self.thresholds.to_dict(), "rule": RULE.format(**self.thresholds.to_dict())}


def entangled(height_kept, cluster_fraction, thresholds: Thresholds = DEFAULT_THRESHOLDS) -> np.ndarray:
    """Per sample: the packing keeps its height and holds one majority cluster (bool array)."""
    h = np.asarray(height_kept, dtype=float)
    f = np.asarray(cluster_fraction, dtype=float)
    return (h >= thresholds.height_kept) & (f >= thresholds.cluster)


def persistence(times, t0: float, is_entangled) -> float:
    """Fraction of the test [t0, t_end] spent entangled, tau = t_entangled / T.

    Each sample stands for the interval since the previous one (the first for [t0, t_1]),
    so unevenly spaced samples are weighted by the time they cover.

    Parameters
    ----------
    times : (K,) float
        Sample times (s), increasing, all > ``t0``.
    t0 : float
        Start of the test (s).
    is_entangled : (K,) bool
        :func:`entangled` at each sample.
    """
    t = np.asarray(times, dtype=float)
    e = np.asarray(is_entangled, dtype=bool)
    if t.size == 0:
        raise RodwarpError("no samples of the stability test to judge; run a test longer than --save-every")
    w = np.diff(np.concatenate([[t0], t]))
    if np.any(w < 0):
        raise RodwarpError("stability-test samples are not in time order")
    total = float(w.sum())
    if total <= 0:
        return float(e[-1])
    return float(w[e].sum() / total)


def judge(times, t0: float, height_kept, cluster_fraction, rods_left=None,
          thresholds: Thresholds = DEFAULT_THRESHOLDS) -> Verdict:
    """The stability verdict from the series of one test.

    Parameters
    ----------
    times : (K,) float
        Sample times of the test (s), after its start ``t0``.
    t0 : float
        Start of the test (s).
    height_kept : (K,) float
        h(t) = y_c(t) / y_c(t0), centroid heights above the floor.
    cluster_fraction : (K,) float
        f(t), largest contact cluster over all rods.
    rods_left : (K,) float, optional
        Fraction of rods that left the pile (reported, not used by the rule).
    thresholds : Thresholds
        The rule's thresholds.

    Returns
    -------
    Verdict
        ``stable`` and the end values of h, f, rods left, with the persistence tau.
    """
    t = np.asarray(times, dtype=float)
    h = np.asarray(height_kept, dtype=float)
    f = np.asarray(cluster_fraction, dtype=float)
    if not (t.shape == h.shape == f.shape) or t.ndim != 1:
        raise RodwarpError("times, height_kept and cluster_fraction must be 1-D series of one length")
    if not (np.all(np.isfinite(h)) and np.all(np.isfinite(f))):
        raise RodwarpError("height_kept or cluster_fraction has NaN/inf samples: the run did not finish cleanly")
    ent = entangled(h, f, thresholds)
    tau = persistence(t, t0, ent)
    left = None
    if rods_left is not None:
        r = np.asarray(rods_left, dtype=float)
        left = float(r[-1]) if r.size else None
    stable = bool(ent[-1] and tau >= thresholds.persistence)
    return Verdict(stable, float(h[-1]), tau, float(f[-1]), left, thresholds)


def judge_rows(rows, t0: float, thresholds: Thresholds = DEFAULT_THRESHOLDS, stage: str | None = None) -> Verdict:
    """:func:`judge` on metric rows (dicts with ``time``, ``stage``, ``height_kept``,
    ``largest_cluster_fraction``, ``rods_left``) of the test stage (named ``stage``; None: the
    stage of the first judged row, the first with a ``height_kept``)."""
    if stage is None:
        stage = next((r["stage"] for r in rows if r.get("height_kept") not in (None, "")), None)
    test = [r for r in rows if r["stage"] == stage and float(r["time"]) > t0]
    if not test:
        raise RodwarpError("no samples of the stability test to judge; run a test longer than --save-every")
    col = lambda k: [float(r[k]) for r in test]  # noqa: E731
    left = col("rods_left") if all(r.get("rods_left") not in (None, "") for r in test) else None
    return judge(col("time"), t0, col("height_kept"), col("largest_cluster_fraction"), left, thresholds)


def judge_metrics_csv(path, t0: float | None = None, thresholds: Thresholds = DEFAULT_THRESHOLDS) -> Verdict:
    """Judge a finished run again from its ``metrics.csv`` (e.g. with other thresholds).

    ``t0`` (the test's start, s) defaults to the time of the first test row's predecessor
    (the test's rows are those with a ``height_kept``): the last sample before the test, or
    the first test sample itself.
    """
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows or "height_kept" not in rows[0]:
        raise RodwarpError(f"{path} has no height_kept column: it was written by an older rodwarp; rerun the run")
    if t0 is None:
        idx = next((i for i, r in enumerate(rows) if r["height_kept"] != ""), None)
        if idx is None:
            raise RodwarpError(f"{path} has no stability-test rows")
        t0 = float(rows[idx - 1]["time"]) if idx > 0 else float(rows[idx]["time"])
    return judge_rows(rows, t0, thresholds)


# ----------------------------------------------------------------------------- the landed phase

#: samples per drive period below which a cycle's lowest sample may miss the landed packing
LANDED_SAMPLES = 4
#: the landed measures average the last this many whole cycles of the test
LANDED_LAST = 5

LANDED_RULE = ("per whole drive cycle N of the test (samples with N - 1 < (t - t0) f <= N), the sample with the "
               "lowest centroid: the packing landed, not in flight; h and f there, averaged over the last "
               "{last} cycles; persistence = the share of cycles whose landed sample has h >= {height_kept:g} and "
               "f >= {cluster:g}; stable = both means above those thresholds and persistence >= {persistence:g}")


def samples_per_cycle(params) -> float:
    """Samples the stability test takes per drive period: ``samples_per_cycle`` when set, else
    1 / (freq save_every); 0 for a test without a drive."""
    if not params.freq > 0:
        return 0.0
    k = getattr(params, "samples_per_cycle", None)
    return float(k) if k else 1.0 / (params.freq * params.save_every)


def landed_samples(t, y, freq: float) -> tuple[np.ndarray, np.ndarray]:
    """Per whole drive cycle N = 1, 2, ... (samples with N - 1 < t f <= N), the index of the
    sample with the lowest height ``y``: the packing landed. ``t`` is the time since the drive
    began (s). Returns (cycles, indices); cycles without a sample are left out."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    k = np.ceil(t * freq - 1e-9).astype(int)
    cyc = np.unique(k[k >= 1])
    idx = np.array([np.flatnonzero(k == c)[np.argmin(y[k == c])] for c in cyc], dtype=int)
    return cyc, idx


def landed(times, t0: float, freq: float, height_kept, cluster_fraction, per_cycle: float,
           thresholds: Thresholds = DEFAULT_THRESHOLDS, last: int = LANDED_LAST) -> dict:
    """The phase-aware measures of a vibration test: h and f where the packing has landed.

    A sample at one fixed time may catch a thrown pile in the air (h of 2 to 5 at the end of a
    test whose floor moves by half a rod length). Here each whole drive cycle contributes its
    sample of lowest centroid height, the landed packing; the measures are the means of h and
    f at those samples over the last ``last`` cycles, the persistence over every cycle, and the
    verdict's rule applied to them.

    Parameters
    ----------
    times : (K,) float
        Sample times of the test (s), after its start ``t0`` (s).
    freq : float
        The test's drive frequency (Hz).
    height_kept, cluster_fraction : (K,) float
        h(t) and f(t) at the samples.
    per_cycle : float
        Samples per drive period; below :data:`LANDED_SAMPLES` the landing is not resolved and
        the measures are None (``why`` says so).
    thresholds : Thresholds
        The verdict's thresholds.
    last : int
        Cycles averaged (fewer when the test has fewer whole cycles; ``cycles_averaged`` says).

    Returns
    -------
    dict
        ``height_kept``, ``largest_cluster_fraction``, ``persistence``, ``stable`` (None when not
        resolved), ``cycles`` (whole cycles sampled), ``cycles_averaged``, ``samples_per_cycle``,
        ``per_cycle`` (cycle, h, f of every landed sample), ``rule`` and ``why`` (None or why the
        measures are missing).
    """
    out = {"height_kept": None, "largest_cluster_fraction": None, "persistence": None, "stable": None,
           "cycles": 0, "cycles_averaged": 0, "samples_per_cycle": float(per_cycle),
           "per_cycle": {"cycle": [], "height_kept": [], "largest_cluster_fraction": []},
           "rule": LANDED_RULE.format(last=last, **thresholds.to_dict()), "why": None}
    if not freq > 0:
        out["why"] = "the test has no drive: there is no cycle to find the landing in"
        return out
    if per_cycle < LANDED_SAMPLES - 1e-9:
        out["why"] = (f"{per_cycle:.3g} samples per drive cycle; the landed phase needs at least {LANDED_SAMPLES} "
                      f"(--samples-per-cycle 8)")
        return out
    t = np.asarray(times, dtype=float) - t0
    h = np.asarray(height_kept, dtype=float)
    f = np.asarray(cluster_fraction, dtype=float)
    # a cycle is whole when the test reached its end (the last sample may close it a hair early)
    whole = t * freq <= np.floor(t[-1] * freq + 1e-6) + 1e-9 if t.size else t > 0
    cyc, idx = landed_samples(t[whole], h[whole], freq)
    if cyc.size == 0:
        out["why"] = "the test is shorter than one drive cycle"
        return out
    hl, fl = h[whole][idx], f[whole][idx]
    n = min(last, cyc.size)
    ent = entangled(hl, fl, thresholds)
    tau = float(np.mean(ent))
    h_mean, f_mean = float(np.mean(hl[-n:])), float(np.mean(fl[-n:]))
    out.update({"height_kept": h_mean, "largest_cluster_fraction": f_mean, "persistence": tau,
                "stable": bool(h_mean >= thresholds.height_kept and f_mean >= thresholds.cluster
                               and tau >= thresholds.persistence),
                "cycles": int(cyc.size), "cycles_averaged": int(n),
                "per_cycle": {"cycle": cyc.tolist(), "height_kept": hl.tolist(),
                              "largest_cluster_fraction": fl.tolist()}})
    return out


def landed_rows(rows, t0: float, freq: float, per_cycle: float, thresholds: Thresholds = DEFAULT_THRESHOLDS,
                stage: str | None = None) -> dict:
    """:func:`landed` on metric rows (dicts as in metrics.csv) of the test stage ``stage``
    (None: the stage of the first row with a ``height_kept``)."""
    if stage is None:
        stage = next((r["stage"] for r in rows if r.get("height_kept") not in (None, "")), None)
    test = [r for r in rows if r["stage"] == stage and float(r["time"]) > t0]
    col = lambda k: [float(r[k]) for r in test]  # noqa: E731
    return landed(col("time"), t0, freq, col("height_kept"), col("largest_cluster_fraction"), per_cycle, thresholds)


# ----------------------------------------------------------------------------- pile geometry


@dataclass(frozen=True)
class PileReference:
    """The pile when the test starts: the reference of h(t) and of rods left.

    Attributes
    ----------
    time : float
        Test start t0 (s).
    height : float
        Mass centroid height above the floor y_c(t0) (m).
    axis : (2,) float
        Horizontal position (x, y) of the mass centroid (m): the pile's vertical axis.
    radius : float
        Rods whose centroid lies farther than this from the axis have left the pile (m):
        the farthest rod centroid at t0 plus half the longest rod.
    low : float
        Rods outside the largest cluster whose centroid is below this height above the
        floor lie on the floor, out of the pile (m): two diameters.
    """

    time: float
    height: float
    axis: tuple
    radius: float
    low: float

    def to_dict(self) -> dict:
        return {"time": self.time, "height": self.height, "axis": list(self.axis), "radius": self.radius,
                "low": self.low}

    @classmethod
    def from_dict(cls, d: dict) -> "PileReference":
        return cls(float(d["time"]), float(d["height"]), tuple(float(v) for v in d["axis"]), float(d["radius"]),
                   float(d["low"]))


def rod_centroids(x: np.ndarray, vertex_rod: np.ndarray, mass: np.ndarray, n_rods: int) -> np.ndarray:
    """Mass centroid of every rod (N, 3) in the units of ``x``."""
    w = np.bincount(vertex_rod, weights=mass, minlength=n_rods)
    return np.stack([np.bincount(vertex_rod, weights=mass * x[:, k], minlength=n_rods) for k in range(3)],
                    axis=1) / np.maximum(w, 1e-300)[:, None]


def centroid_height_above(x: np.ndarray, mass: np.ndarray, floor: float) -> float:
    """Mass-weighted mean vertex height above the floor plane z = ``floor`` (m)."""
    return float(np.average(x[:, 2], weights=mass) - floor)


def pile_reference(t0: float, x, vertex_rod, mass, n_rods: int, floor: float, rod_length: float,
                   diameter: float) -> PileReference:
    """:class:`PileReference` of the positions ``x`` (V, 3) at the test start, floor at z = ``floor``."""
    x = np.asarray(x, dtype=float)
    h = centroid_height_above(x, mass, floor)
    if not h > 0:
        raise RodwarpError(f"the packing's centroid is not above the floor (height {h:.3g} m) when the test starts")
    axis = np.average(x[:, :2], axis=0, weights=mass)
    c = rod_centroids(x, vertex_rod, mass, n_rods)
    r = float(np.max(np.linalg.norm(c[:, :2] - axis, axis=1))) + 0.5 * rod_length
    return PileReference(float(t0), h, (float(axis[0]), float(axis[1])), r, 2.0 * diameter)


def rods_left(x, vertex_rod, mass, n_rods: int, floor: float, in_largest: np.ndarray, ref: PileReference) -> float:
    """Fraction of rods that have left the pile.

    A rod has left when its centroid lies beyond ``ref.radius`` from the pile's axis, or
    when it is outside the largest contact cluster and its centroid is below ``ref.low``
    above the floor (it lies on the floor on its own).

    Parameters
    ----------
    x : (V, 3) float
        Vertex positions (m).
    in_largest : (N,) bool
        Whether each rod belongs to the largest contact cluster.
    """
    c = rod_centroids(np.asarray(x, float), vertex_rod, mass, n_rods)
    far = np.linalg.norm(c[:, :2] - np.asarray(ref.axis), axis=1) > ref.radius
    low = (c[:, 2] - floor < ref.low) & ~np.asarray(in_largest, bool)
    return float(np.count_nonzero(far | low) / max(n_rods, 1))
