r"""Sparse Bayesian learning solvers (type-II maximum likelihood for the RVM): the public face.

Modules outside ``bayes_fdi/rvm/sbl/`` import from here only. Four solvers share one result
type, :class:`SBLResult`:

* :func:`fast_gaussian` / :func:`fast_bernoulli` -- the sequential marginal-likelihood
  maximisation of Tipping & Faul (2003), "Fast marginal likelihood maximisation for sparse
  Bayesian models" (AISTATS), as realised in SparseBayes v2: candidate factors ``S, Q``, one
  add / re-estimate / delete per iteration chosen by the largest exact evidence gain,
  deletions first, a cache ``B^T Phi`` growing one column per addition, the alignment test
  and the SparseBayes stopping rules. Unlike SparseBayes, the posterior is refactorised after
  every addition, deletion and noise update (re-estimations move the factor by a rank-one step
  within an error budget) and every decision is taken on exact factors
  (:mod:`~bayes_fdi.rvm.sbl.decisions`). In :mod:`~bayes_fdi.rvm.sbl.gaussian` and
  :mod:`~bayes_fdi.rvm.sbl.bernoulli`.
* :func:`em_gaussian` / :func:`em_bernoulli` -- the classical re-estimation of Tipping (2001),
  "Sparse Bayesian learning and the relevance vector machine" (JMLR), eqs. (10)-(11) and
  (26)-(29): ``alpha_i = gamma_i/mu_i^2``, ``sigma^2 = ||t - Phi mu||^2 / (N - sum gamma)``,
  pruning large ``alpha`` (:mod:`~bayes_fdi.rvm.sbl.reestimation`).
* :func:`polish_gaussian` -- a fast fit polished by a re-estimation restart
  (:mod:`~bayes_fdi.rvm.sbl.polish`).

All solvers work on unit-norm basis columns internally and rescale weights, covariance and
precisions to the caller's basis at output (:mod:`~bayes_fdi.rvm.sbl.result`). The log evidence
is the exact log marginal likelihood ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)`` (Gaussian,
including the ``-N/2 log 2 pi`` constant) or its Laplace approximation (Bernoulli).

Also exported, for the estimators and for checking the solvers: the candidate basis
(:class:`Design`, its screening copy :class:`TriangleCopy`), the numerics
(:func:`factor_precision`, :func:`rounding_gamma`, :func:`thin_matmul`,
:func:`grown_capacity`), the decision rules (:func:`best_action`,
:func:`lowest_index_in_band`, the exact and screened factors, the verification of actions) and
the carried screening factors (:class:`TrackedFactors`).

The modules, bottom up (each imports only modules above it in this list):
``screening_copy``, ``design``; ``precision_factor``, ``rounding``, ``noise``, ``capacity`` (the
growth of the Gaussian solver's column buffers); ``result``;
``decisions``, ``action_kernels``, ``tracked_kernels``, ``factor_kernels`` (numba kernels of
the decision rules, of the carried factors' re-estimation update and of the posterior's terms and
factor update, used on the CPU in float64);
``residual_factors``, ``screening``; ``verification``; ``alignment``;
``posterior_bounds``; ``tracked_compiled`` (the carried factors' compiled paths);
``tracked_factors``; ``laplace``; ``gaussian``, ``bernoulli``;
``reestimation``; ``polish``.
"""

from __future__ import annotations

from bayes_fdi.rvm.sbl.bernoulli import fast_bernoulli
from bayes_fdi.rvm.sbl.capacity import grown_capacity
from bayes_fdi.rvm.sbl.decisions import Action, best_action, lowest_index_in_band
from bayes_fdi.rvm.sbl.design import DEFAULT_MAX_BYTES, Design
from bayes_fdi.rvm.sbl.gaussian import fast_gaussian
from bayes_fdi.rvm.sbl.laplace import LaplaceMode, posterior_mode
from bayes_fdi.rvm.sbl.polish import Polish, polish_gaussian, restart_pool
from bayes_fdi.rvm.sbl.posterior_bounds import posterior_context
from bayes_fdi.rvm.sbl.precision_factor import (
    NumericalWarning,
    PrecisionFactor,
    cholesky_jitter,
    factor_precision,
)
from bayes_fdi.rvm.sbl.reestimation import em_bernoulli, em_gaussian
from bayes_fdi.rvm.sbl.residual_factors import exact_factors, weighted_exact_factors
from bayes_fdi.rvm.sbl.result import SBLResult
from bayes_fdi.rvm.sbl.rounding import rounding_gamma, thin_matmul
from bayes_fdi.rvm.sbl.screening import gaussian_screened_Q, screened_factors
from bayes_fdi.rvm.sbl.screening_copy import ENTRY_BYTES, TriangleCopy, triangle_bytes
from bayes_fdi.rvm.sbl.tracked_factors import TrackedFactors
from bayes_fdi.rvm.sbl.verification import (
    lazy_verified_action,
    optimistic_ratio,
    reestimate_gain_bounds,
    useful_lower_bound,
    verified_action,
    verified_argmax,
)

__all__ = [
    "DEFAULT_MAX_BYTES",
    "ENTRY_BYTES",
    "Action",
    "Design",
    "LaplaceMode",
    "NumericalWarning",
    "Polish",
    "PrecisionFactor",
    "SBLResult",
    "TrackedFactors",
    "TriangleCopy",
    "best_action",
    "cholesky_jitter",
    "em_bernoulli",
    "em_gaussian",
    "exact_factors",
    "factor_precision",
    "fast_bernoulli",
    "fast_gaussian",
    "gaussian_screened_Q",
    "grown_capacity",
    "lazy_verified_action",
    "lowest_index_in_band",
    "optimistic_ratio",
    "polish_gaussian",
    "posterior_context",
    "posterior_mode",
    "reestimate_gain_bounds",
    "restart_pool",
    "rounding_gamma",
    "screened_factors",
    "thin_matmul",
    "triangle_bytes",
    "useful_lower_bound",
    "verified_action",
    "verified_argmax",
    "weighted_exact_factors",
]
