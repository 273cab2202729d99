"""Relevance Vector Machines (sparse Bayesian learning) in torch.

``RVR`` (regression) and ``RVC`` (classification) are scikit-learn estimators fitted by
Tipping & Faul's fast marginal-likelihood maximisation (``method="fast"``) or Tipping's
re-estimation (``method="em"``); ``load`` restores a model written by ``.save``.

The public face of the RVMs (other parts of the package also use :mod:`~bayes_fdi.rvm.kernels`
and :mod:`~bayes_fdi.rvm.threads` directly). The sparse Bayesian solvers behind the estimators
are in :mod:`bayes_fdi.rvm.sbl`, whose own face is the only way in; full posteriors (by
sampling) in :mod:`bayes_fdi.rvm.posterior`. Nothing in ``bayes_fdi.rvm`` knows of actuators.
"""

from bayes_fdi.rvm.classification import RVC
from bayes_fdi.rvm.kernels import RBF, Kernel, Linear, Polynomial, Product, Scaled, Sum
from bayes_fdi.rvm.loading import load
from bayes_fdi.rvm.regression import RVR
from bayes_fdi.rvm.sbl import NumericalWarning, SBLResult

__all__ = [
    "RBF",
    "RVC",
    "RVR",
    "Kernel",
    "Linear",
    "NumericalWarning",
    "Polynomial",
    "Product",
    "SBLResult",
    "Scaled",
    "Sum",
    "load",
]
