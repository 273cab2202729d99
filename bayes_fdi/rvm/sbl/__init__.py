r"""Sparse Bayesian learning solvers (type-II maximum likelihood for the RVM), gathered.

Four solvers share one result type, :class:`SBLResult` (:mod:`bayes_fdi.rvm.sbl.precision_factor`):

* :func:`fast_gaussian` / :func:`fast_bernoulli` -- Tipping & Faul (2003) sequential
  marginal-likelihood maximisation as realised in SparseBayes v2 (see
  ``shared/reference/fast-sbl.md``): candidate factors ``S, Q``, one add /
  re-estimate / delete per iteration chosen by the largest exact evidence gain,
  deletions first, a cache ``B^T Phi`` growing one column per addition, the alignment
  test and the SparseBayes stopping rules. Unlike SparseBayes, the posterior is
  refactorised each iteration (no rank-one updates, which drift) and every decision is
  taken on exact factors (:mod:`bayes_fdi.rvm.sbl.decisions`). In
  :mod:`bayes_fdi.rvm.sbl.gaussian` and :mod:`bayes_fdi.rvm.sbl.bernoulli`.
* :func:`em_gaussian` / :func:`em_bernoulli` -- the classical re-estimation of
  Tipping (2001), the paper's eqs. (10)-(11) and (26)-(29): ``alpha_i = gamma_i/mu_i^2``,
  ``sigma^2 = ||t - Phi mu||^2 / (N - sum gamma)``, pruning large ``alpha``
  (:mod:`bayes_fdi.rvm.sbl.reestimation`).

All solvers work on unit-norm basis columns internally and rescale weights,
covariance and precisions to the caller's basis at output.  The log evidence is the
exact log marginal likelihood ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)``
(Gaussian, including the ``-N/2 log 2 pi`` constant) or its Laplace approximation
(Bernoulli).
"""

from __future__ import annotations

from bayes_fdi.rvm.sbl.bernoulli import fast_bernoulli, posterior_mode
from bayes_fdi.rvm.sbl.reestimation import em_bernoulli, em_gaussian
from bayes_fdi.rvm.sbl.gaussian import fast_gaussian
from bayes_fdi.rvm.sbl.polish import Polish, polish_gaussian
from bayes_fdi.rvm.sbl.precision_factor import NumericalWarning, SBLResult, cholesky_jitter

__all__ = [
    "NumericalWarning",
    "Polish",
    "SBLResult",
    "cholesky_jitter",
    "em_bernoulli",
    "em_gaussian",
    "fast_bernoulli",
    "fast_gaussian",
    "polish_gaussian",
    "posterior_mode",
]
