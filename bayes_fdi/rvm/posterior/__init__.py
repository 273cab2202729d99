"""Full posteriors for the sparse Bayesian model behind the RVM (Pyro NUTS / SVI, ArviZ output).

The package is split by concern:

* :mod:`~bayes_fdi.rvm.posterior.hyperpriors` -- :class:`Hyperpriors`;
* :mod:`~bayes_fdi.rvm.posterior.regression_model`,
  :mod:`~bayes_fdi.rvm.posterior.classification_model` -- the Pyro models with their declared
  priors, closed-form potentials and gradients;
* :mod:`~bayes_fdi.rvm.posterior.samplers` -- seeded NUTS chains and SVI;
* :mod:`~bayes_fdi.rvm.posterior.sampling` -- the entry points :func:`sample_posterior` and
  :func:`fit_posterior`;
* :mod:`~bayes_fdi.rvm.posterior.diagnostics` -- R-hat and ESS (from ArviZ) and
  :class:`PosteriorDiagnostics`;
* :mod:`~bayes_fdi.rvm.posterior.results` -- the immutable results :class:`RVMPosterior` and
  :class:`OneVsRestPosterior`;
* :mod:`~bayes_fdi.rvm.posterior.arviz_conversion` -- ``to_arviz()``: ``InferenceData`` with
  ``posterior``, ``sample_stats``, ``observed_data``, ``log_likelihood`` and
  ``posterior_predictive``, so ``az.loo``, ``az.compare`` and ``az.plot_ppc`` work directly.

The fast type-II fit (``RVR`` / ``RVC``) returns point estimates of the hyperparameters: one
precision ``alpha_i`` per basis function and, for regression, the noise precision ``beta``. This
module puts hyperpriors on them and integrates them out:

.. math::

    \\alpha_i \\sim \\mathrm{Gamma}(a_\\alpha, b_\\alpha), \\quad
    \\beta \\sim \\mathrm{Gamma}(a_\\beta, b_\\beta), \\quad
    w_i \\mid \\alpha_i \\sim \\mathcal N(0, \\alpha_i^{-1}),

with a Gaussian likelihood ``t ~ N(Phi w, 1/beta)`` (regression) or a Bernoulli likelihood with
logits ``Phi w`` (classification).

Two model forms are provided, in the style of ``pyro.contrib.gp`` (a class holding the data and the
declared priors, with ``model`` methods):

* :class:`SparseBayesRegressionModel` -- ``model`` is *collapsed*: the weights are integrated
  out analytically and the Gaussian log evidence ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)``
  enters as a ``pyro.factor``; it is computed from the Cholesky factor of the ``M x M`` matrix
  ``A + beta Phi^T Phi`` (Woodbury identity and matrix determinant lemma). NUTS samples
  ``(log alpha, log beta)`` only, and the weights are then drawn exactly from their Gaussian
  conditional ``N(mu, Sigma)``. ``noncentred_model`` keeps the weights, written as
  ``w = z / sqrt(alpha)`` with ``z ~ N(0, I)``; SVI uses it.
* :class:`SparseBayesClassificationModel` -- Bernoulli likelihood; NUTS samples
  ``(log alpha, w)`` (centred, default on the relevance vectors) or ``(log alpha, z)``
  (non-centred); SVI uses the non-centred form.

:func:`fit_posterior` runs it from a fitted estimator (``RVR(...).fit(X, y).fit_posterior(X, y)``),
:func:`sample_posterior` from a model built on an explicit design matrix. Both return an immutable
:class:`RVMPosterior` with posterior draws, ``predict`` (predictions average over the draws),
``diagnostics`` (ArviZ's rank-normalised split R-hat, bulk/tail ESS; divergences per chain) and
``to_arviz()``.

Hyperprior defaults (:class:`Hyperpriors`) and why they are not Tipping's ``1e-6``: with
``a = b = 1e-6`` the prior on ``log alpha`` is flat up to ``alpha ~ 1e6``. The likelihood does not
decay as ``alpha -> infinity`` (the basis is simply switched off), so the posterior of every
weakly-determined ``log alpha`` has a plateau whose mass grows with its length ``log(1/b)``:
posterior answers then depend on an arbitrary constant, and NUTS spends its time wandering along
the plateau; below the data-determined value the posterior of ``log alpha`` decays only like
``alpha^(a + 1/2)``, a long tail when ``a ~ 0``. The defaults ``a_alpha = 1/2``,
``b_alpha = 5e-5`` (rate relative to the target variance) make the implied marginal prior of each
weight a Cauchy distribution with scale ``sqrt(b/a) = 1%`` of the target standard deviation: a
sparsity-favouring prior with heavy tails (data-determined weights are not shrunk), a plateau that
ends at weights too small to matter for prediction, and a light enough lower tail for NUTS to mix
(R-hat < 1.01 without divergences on our test problems). ``beta`` is determined
by all ``N`` residuals, so its prior can stay Tipping-flat (``a_beta = b_beta = 1e-6``; the rate
matches SparseBayes' ``BetaMaxFactor`` floor ``sigma^2 >= var(t) / 1e6``).
"""

from bayes_fdi.rvm.posterior.classification_model import SparseBayesClassificationModel
from bayes_fdi.rvm.posterior.diagnostics import (
    PosteriorDiagnostics,
    effective_sample_size,
    r_hat,
)
from bayes_fdi.rvm.posterior.hyperpriors import Hyperpriors
from bayes_fdi.rvm.posterior.regression_model import SparseBayesRegressionModel
from bayes_fdi.rvm.posterior.results import OneVsRestPosterior, RVMPosterior
from bayes_fdi.rvm.posterior.sampling import fit_posterior, sample_posterior

__all__ = [
    "Hyperpriors",
    "OneVsRestPosterior",
    "PosteriorDiagnostics",
    "RVMPosterior",
    "SparseBayesClassificationModel",
    "SparseBayesRegressionModel",
    "effective_sample_size",
    "fit_posterior",
    "r_hat",
    "sample_posterior",
]
