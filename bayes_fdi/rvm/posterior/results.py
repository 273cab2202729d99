"""Immutable posterior results: draws, predictions averaged over them, ArviZ export.

:class:`RVMPosterior` holds the draws of one sparse Bayesian model (and the training design and
targets, for the pointwise log-likelihood and posterior predictive checks);
:class:`OneVsRestPosterior` holds one binary posterior per class of a multi-class RVC. Both are
frozen dataclasses whose arrays are read-only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from bayes_fdi.rvm.posterior.arviz_conversion import one_vs_rest_to_arviz, rvm_posterior_to_arviz
from bayes_fdi.rvm.posterior.diagnostics import PosteriorDiagnostics
from bayes_fdi.rvm.posterior.hyperpriors import Hyperpriors
from bayes_fdi.rvm.posterior.numpy_bridge import DTYPE, LOG_2PI

__all__ = ["OneVsRestPosterior", "RVMPosterior"]


def _readonly(x: Any) -> np.ndarray | None:
    if x is None:
        return None
    x = np.array(x, dtype=np.float64, copy=True)
    x.flags.writeable = False
    return x


@dataclass(frozen=True, eq=False)
class RVMPosterior:
    """Posterior draws of a sparse Bayesian model; immutable.

    Attributes
    ----------
    kind : {"regression", "classification"}
    inference : {"nuts", "svi"}
    basis : str
        ``"active"`` (basis chosen by type-II ML), ``"all"``, or ``"design"`` (explicit matrix).
    log_alpha : numpy.ndarray, shape (chains, draws, M)
    log_beta : numpy.ndarray or None, shape (chains, draws)
        Log noise precision (regression only).
    weights : numpy.ndarray, shape (chains, draws, M)
    diagnostics : PosteriorDiagnostics
    hyperpriors : Hyperpriors
        Absolute hyperpriors used.
    basis_names : tuple of str
    classes : numpy.ndarray or None
        ``[negative, positive]`` labels for classification.
    design : callable or None
        Maps inputs ``X`` to the design matrix; None means ``predict`` takes design matrices.
    train_design : numpy.ndarray or None, shape (n, M)
        Design matrix of the training data the posterior conditions on.
    observed : numpy.ndarray or None, shape (n,)
        Training targets: regression values, or 0/1 (1 = ``classes[1]``) for classification.
        With ``train_design`` it gives :meth:`pointwise_log_likelihood` and
        :meth:`posterior_predictive`; both are None only for a posterior built by hand.
    """

    kind: str
    inference: str
    basis: str
    log_alpha: np.ndarray = field(repr=False)
    log_beta: np.ndarray | None = field(repr=False)
    weights: np.ndarray = field(repr=False)
    diagnostics: PosteriorDiagnostics
    hyperpriors: Hyperpriors
    basis_names: tuple[str, ...] = field(repr=False)
    classes: np.ndarray | None = field(default=None, repr=False)
    design: Callable[[Any], Any] | None = field(default=None, repr=False)
    train_design: np.ndarray | None = field(default=None, repr=False)
    observed: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name in ("log_alpha", "log_beta", "weights", "train_design", "observed"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        if self.classes is not None:
            classes = np.array(self.classes, copy=True)
            classes.flags.writeable = False
            object.__setattr__(self, "classes", classes)
        if self.weights.ndim != 3 or self.log_alpha.shape != self.weights.shape:
            raise ValueError("weights and log_alpha must both have shape (chains, draws, M)")
        if len(self.basis_names) != self.weights.shape[2]:
            raise ValueError("basis_names must have one entry per basis function")
        if (self.train_design is None) != (self.observed is None):
            raise ValueError("give both train_design and observed, or neither")
        if self.observed is not None and (
            self.observed.ndim != 1
            or self.train_design.shape != (self.observed.size, self.weights.shape[2])
        ):
            raise ValueError("train_design must have shape (n, M) for n observed targets")

    @property
    def n_draws(self) -> int:
        """Total number of posterior draws (chains x draws)."""
        return int(self.weights.shape[0] * self.weights.shape[1])

    def _design(self, X: Any) -> torch.Tensor:
        Phi = self.design(X) if self.design is not None else X
        if not isinstance(Phi, torch.Tensor):
            Phi = torch.as_tensor(np.asarray(Phi, dtype=np.float64))
        if Phi.ndim != 2 or Phi.shape[1] != self.weights.shape[2]:
            raise ValueError(
                f"design matrix must have shape (n, {self.weights.shape[2]}), "
                f"got {tuple(Phi.shape)}"
            )
        if not torch.isfinite(Phi).all():
            raise ValueError("design matrix contains NaN or inf")
        return Phi

    def _latent(self, X: Any, batch_size: int = 4096) -> tuple[torch.Tensor, bool]:
        """Per-draw linear predictor ``Phi w_s``, shape (n, S)."""
        Phi = self._design(X)
        W = torch.tensor(self.weights.reshape(-1, self.weights.shape[2]))
        W = W.to(device=Phi.device, dtype=Phi.dtype if Phi.is_floating_point() else DTYPE)
        Phi = Phi.to(W.dtype)
        out = [Phi[i : i + batch_size] @ W.T for i in range(0, Phi.shape[0], batch_size)]
        return torch.cat(out, 0), isinstance(X, torch.Tensor)

    @staticmethod
    def _out(x: torch.Tensor, as_torch: bool) -> Any:
        return x if as_torch else x.detach().cpu().numpy()

    def predict(self, X: Any, return_std: bool = False) -> Any:
        """Posterior predictive mean (and std) averaged over the posterior draws.

        Regression: the predictive distribution is the mixture over draws ``s`` of
        ``N(phi^T w_s, 1/beta_s)``; its mean is the mean of the means and its variance the total
        variance ``E_s[1/beta_s] + Var_s[phi^T w_s]``. Classification: the class label of highest
        averaged probability (``return_std`` is not defined there).

        Parameters
        ----------
        X : array-like or torch.Tensor
            Inputs (or design matrix when the posterior has no ``design``). numpy in -> numpy out,
            torch in -> torch out.
        return_std : bool
        """
        if self.kind == "classification":
            if return_std:
                raise ValueError("return_std is for regression; use predict_proba for classes")
            proba = self.predict_proba(X)
            idx = np.asarray(
                proba.argmax(1).cpu() if isinstance(proba, torch.Tensor) else proba.argmax(1)
            )
            labels = self.classes if self.classes is not None else np.array([0, 1])
            return labels[idx]
        f, as_torch = self._latent(X)
        mean = f.mean(1)
        if not return_std:
            return self._out(mean, as_torch)
        noise_var = torch.exp(-torch.tensor(self.log_beta, dtype=f.dtype, device=f.device)).mean()
        std = torch.sqrt(noise_var + f.var(1, unbiased=False))
        return self._out(mean, as_torch), self._out(std, as_torch)

    def predict_latent(self, X: Any) -> tuple[Any, Any]:
        """Posterior mean and std of the noise-free function ``phi(x)^T w`` over the draws."""
        f, as_torch = self._latent(X)
        return self._out(f.mean(1), as_torch), self._out(f.std(1, unbiased=False), as_torch)

    def predict_proba(self, X: Any) -> Any:
        """Class probabilities ``(n, 2)`` in ``classes`` order: sigmoid averaged over draws."""
        if self.kind != "classification":
            raise ValueError("predict_proba is only defined for classification posteriors")
        f, as_torch = self._latent(X)
        p = torch.sigmoid(f).mean(1)
        return self._out(torch.stack([1.0 - p, p], 1), as_torch)

    # ---- the training data under each draw: LOO and posterior predictive checks ----------------
    def _train_latent(self) -> np.ndarray:
        """``Phi_train w_s`` per draw, shape (chains, draws, n)."""
        if self.train_design is None:
            raise ValueError(
                "this posterior holds no training data (train_design, observed): it was built by "
                "hand; sample_posterior and fit_posterior record them"
            )
        return self.weights @ self.train_design.T

    def pointwise_log_likelihood(self) -> np.ndarray:
        """``log p(t_i | w_s, beta_s)`` per draw and training point, shape (chains, draws, n).

        Regression: ``log N(t_i | phi_i^T w_s, 1/beta_s)``; classification: the Bernoulli log
        probability ``t_i f - log(1 + e^f)`` of ``f = phi_i^T w_s``. Summed over ``i`` it is the
        model's log likelihood at the draw; ArviZ's ``az.loo`` uses it pointwise.
        """
        f = self._train_latent()
        t = self.observed
        if self.kind == "regression":
            lb = self.log_beta[..., None]
            return 0.5 * (lb - LOG_2PI - np.exp(lb) * (t - f) ** 2)
        return t * f - np.logaddexp(0.0, f)

    def posterior_predictive(self, seed: int = 0) -> np.ndarray:
        """Replicated training targets, one set per draw, shape (chains, draws, n).

        Regression: ``t_rep ~ N(phi_i^T w_s, 1/beta_s)`` (float); classification:
        ``t_rep ~ Bernoulli(sigmoid(phi_i^T w_s))`` as 0/1 integers (1 = ``classes[1]``).
        Seeded by ``seed`` (``numpy.random.default_rng``): same seed, same replicates.
        """
        f = self._train_latent()
        rng = np.random.default_rng(seed)
        if self.kind == "regression":
            return f + np.exp(-0.5 * self.log_beta[..., None]) * rng.standard_normal(f.shape)
        p = 0.5 * (1.0 + np.tanh(0.5 * f))
        return (rng.random(f.shape) < p).astype(np.int64)

    def to_arviz(self, *, seed: int = 0) -> Any:
        """The draws as an ``arviz.InferenceData``.

        Groups: ``posterior`` (``log_alpha``, ``weights`` over dimension ``basis``, and
        ``log_beta`` for regression), ``sample_stats`` (``diverging``, NUTS only) and, when the
        posterior holds its training data (always, from ``sample_posterior`` / ``fit_posterior``),
        ``observed_data``, ``log_likelihood`` (pointwise) and ``posterior_predictive``, all with
        the variable ``y`` over dimension ``observation``. So ``az.loo``, ``az.compare`` and
        ``az.plot_ppc`` work on it directly. ``seed`` seeds the posterior predictive draws.
        """
        return rvm_posterior_to_arviz(self, seed=seed)

    @property
    def _diverging(self) -> np.ndarray:
        chains, draws = self.weights.shape[:2]
        out = np.zeros((chains, draws), dtype=bool)
        for c, idx in enumerate(self.diagnostics.divergent_draws):
            out[c, list(idx)] = True
        return out


@dataclass(frozen=True, eq=False)
class OneVsRestPosterior:
    """Posteriors of a multi-class RVC's one-vs-rest binary problems; immutable.

    Probabilities follow ``RVC``: each binary posterior gives ``p_k(x)`` (sigmoid averaged over its
    draws) and the class probabilities are ``p_k / sum_j p_j``.

    Attributes
    ----------
    classes : numpy.ndarray
        Class labels, in the order of ``posteriors``.
    posteriors : tuple of RVMPosterior
        Binary posterior of "class k against the rest", one per class.
    """

    classes: np.ndarray = field(repr=False)
    posteriors: tuple[RVMPosterior, ...] = field(repr=False)
    kind: str = "classification"

    def __post_init__(self) -> None:
        classes = np.array(self.classes, copy=True)
        classes.flags.writeable = False
        object.__setattr__(self, "classes", classes)
        object.__setattr__(self, "posteriors", tuple(self.posteriors))
        if len(self.posteriors) != classes.size or classes.size < 3:
            raise ValueError("need one binary posterior per class, and at least 3 classes")

    @property
    def inference(self) -> str:
        """``"nuts"`` or ``"svi"``."""
        return self.posteriors[0].inference

    @property
    def diagnostics(self) -> tuple[PosteriorDiagnostics, ...]:
        """Diagnostics of each one-vs-rest posterior, in class order."""
        return tuple(p.diagnostics for p in self.posteriors)

    def predict_proba(self, X: Any) -> Any:
        """Class probabilities ``(n, n_classes)`` in ``classes`` order."""
        cols = [p.predict_proba(X)[:, 1] for p in self.posteriors]
        if isinstance(cols[0], torch.Tensor):
            P = torch.stack(cols, 1)
            return P / P.sum(1, keepdim=True)
        P = np.stack(cols, 1)
        return P / P.sum(1, keepdims=True)

    def predict(self, X: Any, return_std: bool = False) -> Any:
        """Most probable class labels."""
        if return_std:
            raise ValueError("return_std is for regression; use predict_proba for classes")
        proba = self.predict_proba(X)
        idx = proba.argmax(1)
        return self.classes[np.asarray(idx.cpu() if isinstance(idx, torch.Tensor) else idx)]

    def to_arviz(self, *, seed: int = 0) -> Any:
        """One ``InferenceData`` with the variables of each class ``k`` suffixed ``[k]``.

        ``posterior``: ``log_alpha[k]``, ``weights[k]``; ``observed_data``, ``log_likelihood``
        and ``posterior_predictive``: ``y[k]``, the one-vs-rest indicator of class ``k`` (each
        binary problem is its own model, so ``az.loo(idata, var_name="y[k]")`` scores one).
        """
        return one_vs_rest_to_arviz(self, seed=seed)
