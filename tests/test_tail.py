"""rodwarp.analysis.tail_fit: the Clauset-Shalizi-Newman fit of an upper tail, on samples whose
law is known (a Pareto tail above a body, an exponential, a lognormal)."""

from __future__ import annotations

import numpy as np
import pytest

from rodwarp.analysis import TailFit, tail_fit
from rodwarp.errors import RodwarpError

SEEDS = range(6)


def _pareto_with_body(seed: int, a: float = 2.5, xmin: float = 1.0, n_body: int = 3000, n_tail: int = 4000):
    """A flat body on [0.05, xmin) and a Pareto tail p(x) ~ x^-a above xmin (inverse CDF)."""
    rng = np.random.default_rng(seed)
    body = rng.uniform(0.05 * xmin, xmin, n_body)
    tail = xmin * (1.0 - rng.random(n_tail)) ** (-1.0 / (a - 1.0))
    return np.concatenate([body, tail])


def test_recovers_exponent_and_xmin_of_a_pareto_tail():
    a, xmin = 2.5, 1.0
    fits = [tail_fit(_pareto_with_body(s, a, xmin), n_boot=0) for s in SEEDS]
    err_a = np.abs([f.alpha - a for f in fits])
    # se = (a - 1) / sqrt(n_tail) ~ 0.025 here: the median error is within one se, the worst within 3
    assert np.median(err_a) < 0.025
    assert err_a.max() < 0.075
    for f in fits:
        assert abs(f.alpha - a) < 3.5 * f.alpha_se
    # xmin is identifiable only from below (above it the sample is still a Pareto tail), so
    # the KS minimum can sit somewhat above the true xmin, never well below it
    ratio = np.array([f.xmin / xmin for f in fits])
    assert np.median(np.abs(ratio - 1.0)) < 0.05
    assert ratio.min() > 0.95 and ratio.max() < 1.6
    # nothing fits a Pareto tail better than the power law
    for f in fits:
        assert f.exponential["favours"] == "power law"
        assert f.lognormal["favours"] != "lognormal"


def test_bootstrap_does_not_reject_a_true_power_law_and_is_seeded():
    x = _pareto_with_body(0, n_body=1000, n_tail=2000)
    f = tail_fit(x, seed=3, n_boot=60)
    assert isinstance(f, TailFit)
    assert f.gof_p >= 0.1
    assert np.isfinite(f.alpha_se_boot) and 0.3 * f.alpha_se < f.alpha_se_boot < 5 * f.alpha_se
    assert tail_fit(x, seed=3, n_boot=60) == f  # same seed, same answer
    assert f.as_dict()["lognormal"]["favours"] == f.lognormal["favours"]


def test_exponential_data_the_likelihood_ratio_favours_the_exponential():
    for s in range(3):
        x = np.random.default_rng(s).exponential(1.0, 20_000)
        f = tail_fit(x, n_boot=0)
        assert f.exponential["R"] < 0
        assert f.exponential["p"] < 0.01
        assert f.exponential["favours"] == "exponential"
        assert f.exponential["lam"] == pytest.approx(1.0, rel=0.1)  # memoryless: the same rate above xmin
        assert f.verdict.startswith("not a power law")


def test_lognormal_data_the_lognormal_fits_at_least_as_well():
    r_norm = []
    for s in SEEDS:
        x = np.random.default_rng(s).lognormal(0.0, 1.0, 5000)
        f = tail_fit(x, n_boot=0)
        # the power law is a limit of the truncated lognormal: it can never do clearly better
        assert f.lognormal["favours"] != "power law"
        r_norm.append(f.lognormal["R_norm"])
    assert max(r_norm) < 0.0
    assert np.median(r_norm) < -0.9
    # a lognormal's tail is heavier than an exponential's: the exponential never wins there
    assert f.exponential["favours"] != "exponential"


def test_bad_inputs():
    with pytest.raises(RodwarpError, match="at least"):
        tail_fit(np.arange(1.0, 20.0))
    with pytest.raises(RodwarpError):
        tail_fit(np.ones(200))  # every tail is one value: no exponent
    with pytest.raises((RodwarpError, TypeError, ValueError)):
        tail_fit(np.arange(1.0, 200.0), max_quantile=0.2)
    # NaN, inf, zeros and negatives are dropped, not fitted
    x = _pareto_with_body(1)
    dirty = np.concatenate([x, [np.nan, np.inf, 0.0, -1.0]])
    assert tail_fit(dirty, n_boot=0).n == x.size
