"""The upper tail of a distribution: is it a power law? (Clauset, Shalizi & Newman 2009)

:func:`power_law_fit` in ``_stats`` looks for the *widest* range over which a truncated power
law passes a KS test; on the entanglement field that range sits among nearly empty balls
(e from 1e-5 to 0.03), not in the tail the paper's Fig. 4E-F is about.  :func:`tail_fit` asks
the question the way Clauset, Shalizi & Newman (SIAM Review 51, 661, 2009; "CSN" below) do:

1. a continuous power law p(x) = (a - 1) / xmin (x / xmin)^-a for x >= xmin, with a by maximum
   likelihood and xmin the candidate that minimises the Kolmogorov-Smirnov distance between
   the tail and the fitted law (CSN section 3);
2. a goodness-of-fit p-value by their semi-parametric bootstrap (section 4.1);
3. Vuong's likelihood-ratio test against a lognormal and an exponential fitted by maximum
   likelihood to the same tail, both truncated at xmin (section 5).

A power law is only *supported* when the bootstrap does not reject it (p >= 0.1 in CSN) and
neither alternative fits significantly better; passing the KS test alone says little when a
lognormal passes it too.  Every test here assumes independent samples: the voxels of a
mesoscopic field are balls that overlap their neighbours, so the standard error is too small
and the p-values too extreme (a large field rejects any model that is not exactly right).

NumPy/SciPy only.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import optimize, special

from rodwarp.errors import RodwarpError
from rodwarp.arguments import real, whole

__all__ = ["TailFit", "tail_fit"]


@dataclass(frozen=True)
class TailFit:
    """What :func:`tail_fit` found; :meth:`as_dict` gives plain values for JSON.

    Attributes
    ----------
    alpha : float
        Exponent a of the density p(x) ~ x^-a for x >= xmin (maximum likelihood).
    alpha_se : float
        Its standard error (a - 1) / sqrt(n_tail) (CSN eq. 3.2), for independent samples.
    alpha_se_boot : float
        The spread (standard deviation) of a over the bootstrap's synthetic samples, which
        includes the uncertainty of xmin; NaN without a bootstrap.
    xmin : float
        Lower bound of the tail, in the units of the values.
    xmax : float
        Largest value.
    decades : float
        log10(xmax / xmin): how far the tail reaches.
    n : int
        Positive finite values used.
    n_tail : int
        Values >= xmin.
    xmin_at_limit : bool
        xmin is the highest candidate allowed (``max_quantile``, ``min_tail``): the KS distance
        was still falling, the tail the data would pick lies further out than allowed.
    ks : float
        KS distance between the tail and the fitted power law.
    gof_p : float
        Share of synthetic samples (drawn from the fitted law above xmin and from the data
        below it, then refitted with their own xmin) whose KS distance is at least ``ks``; a
        power law is ruled out when it is small (CSN: below 0.1). NaN without a bootstrap.
    n_boot : int
        Synthetic samples drawn.
    lognormal, exponential : dict
        The alternative fitted to the same tail (truncated at xmin) and Vuong's test against
        it: the fitted parameters (``mu``, ``sigma`` of ln x; ``lam``, 1 / units of x),
        ``R`` (log-likelihood ratio, power law minus alternative: positive favours the power
        law), ``R_norm`` (R / (sqrt(n_tail) * standard deviation of the pointwise ratios)),
        ``p`` (two-sided: the probability of so large a \\|R_norm\\| if both fit equally well)
        and ``favours`` ("power law", the alternative's name, or "neither" when p >= 0.1).
    verdict : str
        One sentence from the above.
    """

    alpha: float
    alpha_se: float
    alpha_se_boot: float
    xmin: float
    xmax: float
    decades: float
    n: int
    n_tail: int
    xmin_at_limit: bool
    ks: float
    gof_p: float
    n_boot: int
    lognormal: dict = field(default_factory=dict)
    exponential: dict = field(default_factory=dict)
    verdict: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


# ----------------------------------------------------------------------------------------------
# the power law above xmin
# ----------------------------------------------------------------------------------------------

def _candidate_starts(n: int, min_tail: int, max_quantile: float, candidates: int) -> np.ndarray:
    """Indices i into the sorted sample whose value x[i] is tried as xmin.

    Tail sizes m = n - i are spaced geometrically from the whole sample down to the smallest
    tail allowed (``min_tail`` values, and xmin no higher than the ``max_quantile`` quantile),
    so that the resolution in xmin is finest where the tail is short, as with CSN's scan of
    every distinct value, at a cost that does not grow with n (the bootstrap refits hundreds
    of times).
    """
    m_lo = max(min_tail, int(np.ceil((1.0 - max_quantile) * n)))
    m = np.unique(np.round(np.geomspace(n, m_lo, candidates)).astype(np.int64))
    return np.sort(n - m)


def _scan(x: np.ndarray, starts: np.ndarray):
    """The CSN fit over the candidate xmins: (alpha, xmin index, ks) of the KS minimum.

    ``x`` is sorted ascending and positive. A candidate equal to the one before it (ties) is
    moved to the first occurrence of its value, so the tail holds every x >= xmin.
    """
    n = x.size
    lx = np.log(x)
    # suffix sums of ln x: sum over the tail in O(1) per candidate
    suffix = np.concatenate([np.cumsum(lx[::-1])[::-1], [0.0]])
    starts = np.unique(np.searchsorted(x, x[starts], side="left"))
    best = (np.inf, 0, np.nan)
    for i in starts:
        m = n - i
        s = suffix[i] - m * lx[i]
        if s <= 0.0:  # every tail value equals xmin: no exponent
            continue
        a = 1.0 + m / s
        # model CDF of the tail; the empirical CDF steps from j/m to (j+1)/m at each value
        cdf = -np.expm1((1.0 - a) * (lx[i:] - lx[i]))
        j = np.arange(m)
        ks = float(max(np.max(np.abs(cdf - j / m)), np.max(np.abs(cdf - (j + 1) / m))))
        if ks < best[0]:
            best = (ks, int(i), a)
    if not np.isfinite(best[0]):
        raise RodwarpError("no candidate xmin leaves a tail with two distinct values")
    return best[2], best[1], best[0]


# ----------------------------------------------------------------------------------------------
# the alternatives, truncated at xmin, and Vuong's test
# ----------------------------------------------------------------------------------------------

def _loglik_power(t: np.ndarray, xmin: float, a: float) -> np.ndarray:
    return np.log(a - 1.0) - np.log(xmin) - a * np.log(t / xmin)


def _fit_exponential(t: np.ndarray, xmin: float):
    """p(x) = lam exp(-lam (x - xmin)) for x >= xmin; the MLE is 1 / mean(x - xmin)."""
    lam = 1.0 / float(np.mean(t - xmin))
    return {"lam": lam}, np.log(lam) - lam * (t - xmin)


def _lognormal_ll(t: np.ndarray, lt: np.ndarray, xmin: float, mu: float, sigma: float) -> np.ndarray:
    z = (lt - mu) / sigma
    # log of the survival function 1 - Phi(z0) through log_ndtr(-z0): stays finite when xmin
    # lies far in the lognormal's upper tail (the regime where it mimics a power law)
    return (-0.5 * z * z - np.log(sigma * np.sqrt(2.0 * np.pi)) - lt
            - special.log_ndtr(-(np.log(xmin) - mu) / sigma))


def _fit_lognormal(t: np.ndarray, xmin: float):
    """Lognormal truncated at xmin, (mu, sigma) of ln x by numerical maximum likelihood.

    Started from the moments of ln x in the tail and from a wide, low-mu start (the truncated
    lognormal approaches a power law as mu -> -inf with sigma^2 ~ -mu); the better optimum
    wins, so the test is not lost to a local optimum.
    """
    lt = np.log(t)

    def nll(p):
        mu, ls = p
        v = -np.sum(_lognormal_ll(t, lt, xmin, mu, np.exp(ls)))
        return v if np.isfinite(v) else 1e300

    m, s = float(lt.mean()), float(max(lt.std(), 1e-3))
    span = float(max(lt.max() - lt.min(), 1e-3))
    best = None
    for start in ((m, np.log(s)), (np.log(xmin) - 2.0 * span, np.log(2.0 * span))):
        r = optimize.minimize(nll, np.array(start), method="Nelder-Mead",
                              options={"xatol": 1e-7, "fatol": 1e-9, "maxiter": 4000})
        if best is None or r.fun < best.fun:
            best = r
    mu, sigma = float(best.x[0]), float(np.exp(best.x[1]))
    return {"mu": mu, "sigma": sigma}, _lognormal_ll(t, lt, xmin, mu, sigma)


def _vuong(ll_power: np.ndarray, ll_alt: np.ndarray, name: str, level: float) -> dict:
    """Vuong's normalised log-likelihood ratio (CSN eq. 5.3-5.4, non-nested form)."""
    d = ll_power - ll_alt
    r = float(d.sum())
    sd = float(d.std())
    if sd == 0.0:
        return {"R": r, "R_norm": 0.0, "p": 1.0, "favours": "neither"}
    r_norm = r / (sd * np.sqrt(d.size))
    p = float(special.erfc(abs(r_norm) / np.sqrt(2.0)))
    favours = "neither" if p >= level else ("power law" if r > 0 else name)
    return {"R": r, "R_norm": float(r_norm), "p": p, "favours": favours}


# ----------------------------------------------------------------------------------------------
# the whole fit
# ----------------------------------------------------------------------------------------------

def tail_fit(values, seed: int = 0, *, n_boot: int = 200, min_tail: int = 50, max_quantile: float = 0.95,
             candidates: int = 100, level: float = 0.1) -> TailFit:
    """Fit a power law to the upper tail of a sample and test it (Clauset, Shalizi & Newman 2009).

    Parameters
    ----------
    values : array_like
        Sample, any shape (e.g. a field's valid voxels); non-finite and non-positive values
        are dropped.
    seed : int
        Seed of the bootstrap's random numbers (the fit itself is deterministic).
    n_boot : int
        Synthetic samples of the goodness-of-fit bootstrap (0 skips it: ``gof_p`` and
        ``alpha_se_boot`` are NaN). CSN's p is known to +-0.01 with 2500 of them; 200 give
        +-0.035, enough to tell 0 from 0.1 and above.
    min_tail : int
        Fewest values the tail may hold (>= 10).
    max_quantile : float
        Highest quantile of the sample tried as xmin (0.5 to 1): at 0.95 the tail holds at
        least 5% of the sample, so that a handful of extreme balls cannot pass for a tail.
    candidates : int
        Candidate xmins, spaced geometrically in the tail's size (2 to 10000).
    level : float
        Significance below which the likelihood-ratio tests pick a side (CSN use 0.1).

    Returns
    -------
    TailFit

    Raises
    ------
    RodwarpError
        Fewer than ``min_tail`` positive values, or no tail with two distinct values.
    """
    seed = whole("seed", seed, ge=0)
    n_boot = whole("n_boot", n_boot, ge=0, le=100_000)
    min_tail = whole("min_tail", min_tail, ge=10)
    max_quantile = real("max_quantile", max_quantile, ge=0.5, le=1.0)
    candidates = whole("candidates", candidates, ge=2, le=10_000)
    level = real("level", level, gt=0.0, lt=1.0)

    x = np.asarray(values, dtype=np.float64).ravel()
    x = np.sort(x[np.isfinite(x) & (x > 0)])
    n = x.size
    if n < min_tail:
        raise RodwarpError(f"a tail fit needs at least min_tail = {min_tail} positive values, got {n}")
    starts = _candidate_starts(n, min_tail, max_quantile, candidates)
    a, i0, ks = _scan(x, starts)
    at_limit = bool(i0 >= np.searchsorted(x, x[starts[-1]], side="left"))
    xmin = float(x[i0])
    t = x[i0:]
    m = t.size

    # goodness of fit: CSN's semi-parametric bootstrap. Each synthetic sample has n values;
    # each is, with probability m / n, drawn from the fitted power law above xmin (inverse
    # CDF), else resampled from the data below xmin; it is then refitted from scratch (xmin
    # too), so p accounts for the freedom of choosing xmin.
    rng = np.random.default_rng(seed)
    body = x[:i0]
    ks_boot, a_boot = [], []
    for _ in range(n_boot):
        n_t = int(rng.binomial(n, m / n)) if body.size else n
        u = rng.random(n_t)
        synth = xmin * (1.0 - u) ** (-1.0 / (a - 1.0))
        if n_t < n:
            synth = np.concatenate([synth, rng.choice(body, n - n_t)])
        synth.sort()
        a_b, _, ks_b = _scan(synth, starts)
        ks_boot.append(ks_b)
        a_boot.append(a_b)
    gof_p = float(np.mean(np.asarray(ks_boot) >= ks)) if n_boot else float("nan")
    se_boot = float(np.std(a_boot, ddof=1)) if n_boot > 1 else float("nan")

    ll_pl = _loglik_power(t, xmin, a)
    par_ln, ll_ln = _fit_lognormal(t, xmin)
    par_ex, ll_ex = _fit_exponential(t, xmin)
    ln = {**par_ln, **_vuong(ll_pl, ll_ln, "lognormal", level)}
    ex = {**par_ex, **_vuong(ll_pl, ll_ex, "exponential", level)}

    fit = TailFit(alpha=float(a), alpha_se=float((a - 1.0) / np.sqrt(m)), alpha_se_boot=se_boot, xmin=xmin,
                  xmax=float(x[-1]), decades=float(np.log10(x[-1] / xmin)), n=int(n), n_tail=int(m),
                  xmin_at_limit=at_limit, ks=float(ks),
                  gof_p=gof_p, n_boot=n_boot, lognormal=ln, exponential=ex)
    return TailFit(**{**asdict(fit), "verdict": _verdict(fit, level)})


def _verdict(f: TailFit, level: float) -> str:
    better = [name for name, r in (("lognormal", f.lognormal), ("exponential", f.exponential))
              if r["favours"] == name]
    if better:
        verb = "fits" if len(better) == 1 else "fit"
        return f"not a power law: a {' and an '.join(better)} {verb} the tail better"
    if np.isfinite(f.gof_p) and f.gof_p < level:
        if f.lognormal["favours"] == "neither":
            return "not a power law (bootstrap p < 0.1); a lognormal fits as well"
        return "not a power law (bootstrap p < 0.1), though it beats the alternatives"
    alt_equal = [name for name, r in (("lognormal", f.lognormal), ("exponential", f.exponential))
                 if r["favours"] == "neither"]
    if alt_equal:
        return f"a power law is not ruled out, but a {' or an '.join(alt_equal)} fits as well"
    if not np.isfinite(f.gof_p):
        return "a power law beats both alternatives (no bootstrap run)"
    return "a power law: not rejected and better than both alternatives"
