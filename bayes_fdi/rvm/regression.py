r"""Relevance Vector Regression (Tipping 2001), the paper's section 3.1.

Model: :math:`t = \Phi w + \varepsilon`, :math:`\varepsilon \sim N(0, \beta^{-1} I)`,
:math:`w_i \sim N(0, \alpha_i^{-1})`, with the basis :math:`\Phi` made of a bias column
and kernel functions centred on the training inputs.  The hyperparameters
:math:`\alpha, \beta` maximise the marginal likelihood (type-II ML) -- by the fast
sequential algorithm of Tipping & Faul (``method="fast"``) or by the classical
re-estimation (``method="em"``, the paper's eqs. 10-11) -- and most :math:`\alpha_i` go
to infinity, leaving a few *relevance vectors*.  Predictions are Gaussian with
mean :math:`\phi_*^\top\mu` and variance :math:`\beta^{-1} + \phi_*^\top\Sigma\phi_*`
(eqs. 13-14).

Imports :mod:`~bayes_fdi.rvm.base`, :mod:`~bayes_fdi.rvm.kernels`, :mod:`~bayes_fdi.rvm.threads`,
:mod:`~bayes_fdi.rvm.width` and the solvers' face :mod:`bayes_fdi.rvm.sbl`.
"""

from __future__ import annotations

import math
from numbers import Integral
from typing import Any

import numpy as np
import torch
from sklearn.base import RegressorMixin
from sklearn.metrics import r2_score
from torch import Tensor

from bayes_fdi.rvm.base import RVMBase, is_torch, power_of_two_scale
from bayes_fdi.rvm.kernels import RBF, Kernel
from bayes_fdi.rvm.sbl import (
    DEFAULT_MAX_BYTES,
    Polish,
    SBLResult,
    em_gaussian,
    fast_gaussian,
    polish_gaussian,
)
from bayes_fdi.rvm.threads import limit_fit_threads
from bayes_fdi.rvm.width import search_width, width_bounds

__all__ = ["RVR"]


class RVR(RegressorMixin, RVMBase):
    """Relevance Vector Regression with a scikit-learn API, computed in torch.

    Parameters
    ----------
    kernel : {"rbf", "linear", "poly", "precomputed"}, Kernel or callable, default "rbf"
        Basis functions ``k(x, x_n)`` centred on the training rows.  ``"precomputed"``:
        ``X`` already is the design matrix (its columns are the candidate basis functions;
        at prediction time pass the same columns evaluated at the new points).  A callable
        ``f(X, Z)`` must return the ``(len(X), len(Z))`` kernel matrix.
    width : float or "auto", default 2.0
        RBF width sigma in ``exp(-||x - z||^2 / (2 sigma^2))``; ``"auto"`` maximises the
        evidence over sigma (see :mod:`bayes_fdi.rvm.width`).  Only used by ``kernel="rbf"``.
    method : {"fast", "em"}, default "fast"
        ``"fast"``: Tipping & Faul sequential marginal-likelihood maximisation (``O(N M)``
        per step); ``"em"``: Tipping's re-estimation from the full basis (``O(N^3)``, a
        reference for small problems).
    bias : bool, default True
        Include a constant basis function (regularised like the others).
    max_iter : int or None, default None
        Iteration limit (a safety net): None means 10000 for "fast", 1000 for "em".
    tol : float, default 1e-3
        Convergence threshold on changes of ``log alpha`` (and ``log beta`` for "em").
    degree, coef0 : int, float
        Polynomial kernel ``(x^T z + coef0)^degree`` for ``kernel="poly"``.
    dtype : {"float64", "float32"}, default "float64"
        Floating-point type of all computations.
    device : str, torch.device or None, default None
        Compute device; None uses the device of torch inputs (CPU for numpy inputs).
    max_kernel_bytes : int, default 2e9
        Materialise the training kernel matrix only up to this size (2 GB: ``N`` up to about
        15 800 in float64). Larger problems on the CPU keep a screening copy of its upper
        triangle within this size (6 bytes an entry: ``N`` up to about 25 800 at 2 GB;
        :mod:`bayes_fdi.rvm.sbl.screening_copy`); beyond, or on other devices, kernel rows are
        computed in blocks for each product (memory ``O(N M)``, slower additions). Either way
        the fit is the same.
    random_state : int or None, default None
        Unused (the algorithm is deterministic); accepted for API compatibility.
    polish : bool, default False
        After the fast fit (at the chosen width for ``width="auto"``), restart Tipping's
        re-estimation from a pool of columns, continue it with the fast solver and keep the
        fit with the higher evidence (:mod:`bayes_fdi.rvm.sbl.polish`). The evidence of a
        kernel basis has many local optima and the greedy fast solver often stops nats below
        the re-estimation's; with a pool covering the basis the polished evidence is at least
        both. Costs about one more fit (see ``docs/rvm.md``). ``method="fast"`` only.
    polish_pool : int, default 1000
        Columns the restart begins with: the whole basis when it has at most this many, else
        the fast fit's basis and the candidates most correlated with its residual. The
        restart costs ``O(N K^2 + K^3)`` per iteration for ``K`` columns.

    Attributes
    ----------
    relevance_vectors_ : ndarray of shape (m, d)
        Training rows whose kernel functions are in the model (``(m, 0)`` if precomputed).
    relevance_indices_ : ndarray of shape (m,)
        Their row indices in the training set (design-column indices if precomputed).
    mean_, covariance_, alpha_ : ndarray
        Posterior mean, covariance and prior precisions over the active basis (bias column
        first when active).
    coef_ : ndarray of shape (m,)
        Posterior mean of the kernel weights (bias excluded).
    intercept_ : float
        Posterior mean of the bias weight (0.0 when the bias is not in the model).
    beta_ : float
        Noise precision; the noise standard deviation is ``beta_ ** -0.5``.
    evidence_trace_ : ndarray
        Log marginal likelihood after each iteration.
    log_evidence_ : float
        Final log marginal likelihood ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)``.
    n_iter_ : int
        Iterations performed.
    converged_ : bool
        Whether a stopping rule (not ``max_iter``) ended the run.
    width_ : float or None
        The RBF width used (the evidence maximiser for ``width="auto"``).
    width_search_ : WidthSearch
        Only with ``width="auto"``: every width tried and its evidence.
    n_features_in_ : int
        Number of input features.
    polish_ : Polish or None
        With ``polish=True``: the log evidence gained over the fast fit (``gain``; 0 when the
        fast fit was kept), the restart's log evidence (``restart_log_evidence``, in the units of
        ``log_evidence_``) and its pool size (``pool_size``). None otherwise.

    Examples
    --------
    >>> import numpy as np
    >>> from bayes_fdi.rvm import RVR
    >>> rng = np.random.default_rng(0)
    >>> X = rng.uniform(-10, 10, (200, 1))
    >>> y = np.sinc(X[:, 0] / np.pi) + 0.1 * rng.standard_normal(200)
    >>> model = RVR(width=2.0).fit(X, y)
    >>> mean, std = model.predict(X[:3], return_std=True)
    """

    def __init__(
        self,
        kernel: str | Kernel = "rbf",
        width: float | str = 2.0,
        method: str = "fast",
        bias: bool = True,
        max_iter: int | None = None,
        tol: float = 1e-3,
        degree: int = 3,
        coef0: float = 1.0,
        dtype: str = "float64",
        device: str | torch.device | None = None,
        max_kernel_bytes: int = DEFAULT_MAX_BYTES,
        random_state: int | None = None,
        polish: bool = False,
        polish_pool: int = 1000,
    ) -> None:
        super().__init__(
            kernel=kernel,
            width=width,
            method=method,
            bias=bias,
            max_iter=max_iter,
            tol=tol,
            degree=degree,
            coef0=coef0,
            dtype=dtype,
            device=device,
            max_kernel_bytes=max_kernel_bytes,
            random_state=random_state,
        )
        self.polish = polish
        self.polish_pool = polish_pool

    def _check_params(self) -> None:
        super()._check_params()
        if not isinstance(self.polish, bool | np.bool_):
            raise ValueError(f"polish must be True or False, got {self.polish!r}")
        if self.polish and self.method != "fast":
            raise ValueError(f"polish applies to method='fast', got method={self.method!r}")
        if (
            not isinstance(self.polish_pool, Integral)
            or isinstance(self.polish_pool, bool)
            or self.polish_pool < 1
        ):
            raise ValueError(f"polish_pool must be a positive integer, got {self.polish_pool!r}")

    def _solve(
        self,
        X: Tensor,
        t: Tensor,
        width: float | None,
        *,
        polish: bool = False,
        x_scale: float = 1.0,
    ) -> tuple[SBLResult, Kernel | None, Polish | None]:
        design, kern = self._design(X, width, rhs=t, x_scale=x_scale)
        solver = fast_gaussian if self.method == "fast" else em_gaussian
        result = solver(design, t, max_iter=self._max_iter(), tol=float(self.tol))
        if not polish:
            return result, kern, None
        result, polished = polish_gaussian(
            design,
            t,
            result,
            pool_size=int(self.polish_pool),
            max_iter=self._max_iter(),
            tol=float(self.tol),
        )
        return result, kern, polished

    @limit_fit_threads
    def fit(self, X: Any, y: Any) -> RVR:
        """Fit the RVR by type-II maximum likelihood.

        Parameters
        ----------
        X : array-like or Tensor of shape (n_samples, n_features)
            Training inputs (``n_samples >= 2``, finite).
        y : array-like or Tensor of shape (n_samples,)
            Finite targets.

        Returns
        -------
        RVR
            The fitted estimator.
        """
        self._check_params()
        X, y = self._validate_fit(X, y, classifier=False)
        Xt, x_scale = self._fit_inputs(X)
        t = torch.tensor(np.array(y, dtype=np.float64), dtype=Xt.dtype, device=Xt.device)
        t_scale = power_of_two_scale(t)
        if t_scale != 1.0:
            t = t / t_scale
        if not bool(torch.isfinite(t).all()):
            raise ValueError(f"y does not fit in {self.dtype} (its magnitudes overflow)")
        search = None
        if self.width == "auto":
            search = search_width(
                lambda w: self._solve(Xt, t, w)[0].log_evidence, 1.0, bounds=width_bounds(Xt)
            )
            width: float | None = search.width * x_scale
            width_s = search.width
        else:
            if self.kernel == "rbf":
                width = float(self.width)
            elif isinstance(self.kernel, RBF):
                width = self.kernel.width
            else:
                width = None
            width_s = self._scaled_width(width, x_scale)
        polish = bool(self.polish)
        result, kern, polished = self._solve(Xt, t, width_s, polish=polish, x_scale=x_scale)
        self._set_state(result, Xt, kern, width, x_scale=x_scale, t_scale=t_scale)
        shift = Xt.shape[0] * math.log(t_scale)  # log evidence in the caller's target units
        self.polish_ = (
            None
            if polished is None
            else polished._replace(restart_log_evidence=polished.restart_log_evidence - shift)
        )
        self._beta_scaled_ = float(result.beta)
        with np.errstate(under="ignore", over="ignore"):
            self.beta_ = float(np.float64(result.beta) / np.float64(t_scale) ** 2)
        if search is not None:
            self.width_search_ = search._replace(
                width=search.width * x_scale,
                log_evidence=search.log_evidence - shift,
                widths=search.widths * x_scale,
                evidences=search.evidences - shift,
                bounds=None
                if search.bounds is None
                else (search.bounds[0] * x_scale, search.bounds[1] * x_scale),
            )
        return self

    def predict(self, X: Any, return_std: bool = False) -> Any:
        """Predictive mean (and standard deviation) at ``X`` (paper eqs. 13-14).

        Parameters
        ----------
        X : array-like or Tensor of shape (n, n_features)
            Inputs.  numpy in -> numpy out; torch in -> torch out on the same device.
        return_std : bool, default False
            Also return ``sqrt(1/beta_ + phi^T Sigma phi)``.

        Returns
        -------
        mean : ndarray or Tensor of shape (n,)
        std : ndarray or Tensor of shape (n,)
            Only when ``return_std``.
        """
        Phi = self._phi(self._inputs(X))
        scale = getattr(self, "_t_scale_", 1.0)
        mean = Phi @ self._mu_
        if scale != 1.0:
            mean = mean * scale
        if not return_std:
            return self._output(mean, X)
        var = 1.0 / self._noise_precision() + ((Phi @ self._Sigma_) * Phi).sum(1)
        std = var.clamp_min(0.0).sqrt()
        if scale != 1.0:
            std = std * scale
        return self._output(mean, X), self._output(std, X)

    def _noise_precision(self) -> float:
        """The noise precision in the model's (rescaled) target units."""
        return getattr(self, "_beta_scaled_", None) or self.beta_

    def score(self, X: Any, y: Any, sample_weight: Any = None) -> float:
        """Coefficient of determination R^2 of the predictive mean (torch inputs accepted)."""
        pred = self.predict(X)
        if is_torch(pred):
            pred = pred.detach().cpu().numpy()
        y_np = y.detach().cpu().numpy() if is_torch(y) else y
        return float(r2_score(y_np, pred, sample_weight=sample_weight))

    @property
    def noise_std_(self) -> float:
        """Estimated noise standard deviation ``beta_ ** -0.5`` (computed without overflow)."""
        return getattr(self, "_t_scale_", 1.0) / math.sqrt(self._noise_precision())
