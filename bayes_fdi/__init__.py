"""bayes_fdi: Bayesian fault detection and isolation for SEVA pneumatic actuators.

Subpackages
-----------
rvm
    Relevance Vector Machines (regression and classification) in torch, with
    type-II maximum likelihood (fast sequential or EM) and optional Pyro posteriors.
actuator
    A re-implementation of the DAMADICS (DABLib) actuator model with its 19 faults.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bayes_fdi")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.1.0"

__all__ = ["__version__"]
