"""Dirichlet calibration and vector scaling of a class distribution: :class:`DirichletScaler`.

``q = softmax(W log(p) + b)`` fitted on held-out data with the ODIR penalty (Kull et al. 2019),
its strength chosen by cross-validation; ``"diagonal"`` is vector scaling, ``"scalar"`` one
temperature.

Written by hand: Dirichlet calibration with the ODIR penalty has no maintained implementation in
the dependencies (the optimiser, a damped Newton method, is a few lines of numpy).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator

from bayes_fdi.calibration.recalibration import (
    LOG_LOSS_RTOL,
    class_indices,
    fold_indices,
    log_probabilities,
    log_softmax,
)

__all__ = ["DEFAULT_REG_GRID", "DirichletScaler"]

#: Default grid of the ODIR penalty searched by :class:`DirichletScaler`'s cross-validation.
DEFAULT_REG_GRID: tuple[float, ...] = (1e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0, 10.0)

_PARAMETRIZATIONS = ("full", "diagonal", "scalar")


class DirichletScaler(BaseEstimator):
    """Recalibrate class distributions with a linear map of the log-probabilities.

    ``q = softmax(W log(p) + b)`` (Kull et al. 2019, *Beyond temperature scaling: obtaining
    well-calibrated multiclass probabilities with Dirichlet calibration*, NeurIPS). ``W`` is
    a ``K x K`` matrix and ``b`` a ``K``-vector, fitted on held-out data by minimising the mean
    negative log-likelihood plus the ODIR penalty (off-diagonal and intercept regularisation)

    ``reg_lambda / (K (K - 1)) * sum_{i != j} W_ij**2 + reg_mu / K * sum_j b_j**2``,

    so that with a strong penalty the map shrinks towards per-class powers
    ``q_k ∝ p_k ** W_kk`` and never to zero (the diagonal is not penalised). ``W = I``,
    ``b = 0`` is the identity on probabilities. Unlike
    :class:`~bayes_fdi.calibration.TemperatureScaler` the map can move probability between
    classes, so the arg-max (the diagnosed class) **can change**: compare the accuracy before
    and after.

    The penalty is chosen by ``cv``-fold cross-validation on the fitting data (folds
    stratified by class and seeded by ``random_state``): the value of ``reg_grid`` with the
    lowest mean held-out NLL (ties, within a relative
    `~bayes_fdi.calibration.recalibration.LOG_LOSS_RTOL`: the larger penalty); ``reg_mu`` is
    tied to ``reg_lambda`` unless given.

    Parameters
    ----------
    parametrization
        ``"full"`` (default): Dirichlet calibration, full ``W`` and ``b``;
        ``"diagonal"``: vector scaling, ``W`` diagonal (one power per class) and ``b``;
        ``"scalar"``: ``W = I / T``, ``b = 0`` (temperature scaling, no penalty, no
        cross-validation).
    reg_lambda
        Off-diagonal penalty; ``None`` (default) chooses it from ``reg_grid`` by
        cross-validation. Ignored unless ``parametrization="full"``.
    reg_mu
        Intercept penalty; ``None`` (default) uses the same value as ``reg_lambda`` (for
        ``"diagonal"``: cross-validated on ``reg_grid``).
    reg_grid
        Penalties tried by the cross-validation.
    cv
        Number of cross-validation folds (>= 2).
    min_samples
        Fewer fitting samples than this, or fewer than ``2 * cv``, and the scaler falls back
        to one temperature (``parametrization="scalar"``), recorded in ``fallback_``.
        ``None`` (default): ``10 * K`` for ``"full"``, ``3 * K`` for ``"diagonal"``.
    input
        ``"proba"`` (default) or ``"logits"`` (unnormalised log-probabilities), as for
        :class:`~bayes_fdi.calibration.TemperatureScaler`.
    floor
        Probabilities below ``floor`` are raised to it before taking logarithms (default
        1e-12, as :class:`~bayes_fdi.calibration.TemperatureScaler`).
    classes
        Column labels; default: the sorted unique labels seen in ``fit``.
    random_state
        Seed of the cross-validation folds.
    max_iter
        Iteration limit of the (damped Newton) optimiser.

    Attributes
    ----------
    coef_ : numpy.ndarray
        ``W``, shape ``(K, K)``; rows are output classes. Adding one constant to a whole
        column of ``W`` leaves the map unchanged for probability input, so compare maps (or
        column-centred ``W``), not raw matrices.
    intercept_ : numpy.ndarray
        ``b``, shape ``(K,)`` (defined up to a common constant).
    reg_lambda_, reg_mu_ : float
        Penalties used for the final fit.
    cv_results_ : dict
        Penalty -> mean held-out NLL (empty when no cross-validation ran).
    classes_ : numpy.ndarray
    nll_before_, nll_after_ : float
        Mean NLL on the fitting data before recalibration and after it (without penalty).
    fallback_ : str or None
        Why the requested parametrization was replaced by ``"scalar"``, else None.
    parametrization_ : str
        The parametrization actually fitted.
    converged_ : bool
    n_samples_ : int
    """

    def __init__(
        self,
        *,
        parametrization: str = "full",
        reg_lambda: float | None = None,
        reg_mu: float | None = None,
        reg_grid: Sequence[float] = DEFAULT_REG_GRID,
        cv: int = 5,
        min_samples: int | None = None,
        input: str = "proba",
        floor: float = 1e-12,
        classes: Sequence | None = None,
        random_state: int | None = 0,
        max_iter: int = 100,
    ) -> None:
        self.parametrization = parametrization
        self.reg_lambda = reg_lambda
        self.reg_mu = reg_mu
        self.reg_grid = reg_grid
        self.cv = cv
        self.min_samples = min_samples
        self.input = input
        self.floor = floor
        self.classes = classes
        self.random_state = random_state
        self.max_iter = max_iter

    def _logits(self, values: Any) -> np.ndarray:
        return log_probabilities(values, input=self.input, floor=self.floor)

    # ---- the optimisation problem
    @staticmethod
    def _basis(k: int, kind: str) -> np.ndarray:
        """Matrix mapping the free parameters to ``vec([W | b])`` (row-major, k x (k+1))."""
        full = np.eye(k * (k + 1))
        if kind == "full":
            return full
        diag_cols = [a * (k + 1) + a for a in range(k)]
        if kind == "diagonal":
            return full[:, diag_cols + [a * (k + 1) + k for a in range(k)]]
        return full[:, diag_cols].sum(axis=1, keepdims=True)

    @staticmethod
    def _identity(k: int, kind: str) -> np.ndarray:
        if kind == "full":
            return np.concatenate([np.eye(k), np.zeros((k, 1))], axis=1).ravel()
        if kind == "diagonal":
            return np.concatenate([np.ones(k), np.zeros(k)])
        return np.ones(1)

    @staticmethod
    def _unpack(theta: np.ndarray, basis: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        m = (basis @ theta).reshape(k, k + 1)
        return m[:, :k], m[:, k]

    def _solve(
        self,
        z: np.ndarray,
        y_idx: np.ndarray,
        kind: str,
        lam: float,
        mu: float,
        theta0: np.ndarray | None = None,
    ) -> tuple[np.ndarray, bool]:
        """Penalised multinomial logistic regression on ``[z, 1]`` by damped Newton steps.

        The objective is convex; Newton's method with a backtracking line search converges in
        a few tens of steps where first-order methods crawl (log-probabilities of a tree are
        strongly correlated). The Hessian is singular along ``W -> W + 1 v^T`` (a constant
        added to every logit) when the penalty does not fix it: steps are least-squares.
        ``theta0`` warm-starts the iteration (the penalty path of the cross-validation).
        """
        n, k = z.shape
        x = np.concatenate([z, np.ones((n, 1))], axis=1)
        onehot = np.zeros((n, k))
        onehot[np.arange(n), y_idx] = 1.0
        basis = self._basis(k, kind)
        pen = np.zeros((k, k + 1))
        if k > 1:
            pen[:, :k] = lam / (k * (k - 1)) * (1.0 - np.eye(k))
        pen[:, k] = mu / k
        pen_phi = basis.T @ (pen.ravel()[:, None] * basis)  # penalty = theta' pen_phi theta
        xx = (x[:, :, None] * x[:, None, :]).reshape(n, -1)

        def value(theta: np.ndarray) -> tuple[float, np.ndarray]:
            m = (basis @ theta).reshape(k, k + 1)
            logq = log_softmax(x @ m.T)
            return float(-np.sum(onehot * logq) / n + theta @ pen_phi @ theta), logq

        theta = self._identity(k, kind) if theta0 is None else np.array(theta0, dtype=np.float64)
        f, logq = value(theta)
        ok = False
        for _ in range(int(self.max_iter)):
            q = np.exp(logq)
            grad_m = ((q - onehot).T @ x) / n
            g = basis.T @ grad_m.ravel() + 2.0 * pen_phi @ theta
            if np.max(np.abs(g)) < 1e-9:
                ok = True
                break
            s = (q[:, :, None] * (np.eye(k)[None] - q[:, None, :])).reshape(n, -1)
            h = (s.T @ xx / n).reshape(k, k, k + 1, k + 1).transpose(0, 2, 1, 3)
            h = basis.T @ h.reshape(k * (k + 1), -1) @ basis + 2.0 * pen_phi
            try:  # positive definite when the penalty fixes every direction: Cholesky
                chol = np.linalg.cholesky(h)
                step = -np.linalg.solve(chol.T, np.linalg.solve(chol, g))
            except np.linalg.LinAlgError:  # singular along W -> W + 1 v^T: least squares
                step = -np.linalg.lstsq(h, g, rcond=1e-12)[0]
            slope = float(g @ step)
            if slope >= 0:  # numerically flat: no descent direction left
                step, slope = -g, -float(g @ g)
            t = 1.0
            while True:
                f_new, logq_new = value(theta + t * step)
                if f_new <= f + 1e-4 * t * slope or t < 1e-10:
                    break
                t *= 0.5
            if t < 1e-10 or f - f_new < 1e-15 * max(1.0, abs(f)):
                ok = f_new <= f and np.max(np.abs(g)) < 1e-6
                if f_new <= f:
                    theta, f = theta + t * step, f_new
                break
            theta, f, logq = theta + t * step, f_new, logq_new
        return theta, ok

    def _nll(self, theta: np.ndarray, z: np.ndarray, y_idx: np.ndarray, kind: str) -> float:
        k = z.shape[1]
        w, b = self._unpack(theta, self._basis(k, kind), k)
        logq = log_softmax(z @ w.T + b)
        return float(-np.mean(logq[np.arange(z.shape[0]), y_idx]))

    def fit(self, proba_or_logits: Any, y: Any) -> DirichletScaler:
        """Fit ``W`` and ``b`` (and choose the penalty) on held-out ``(proba_or_logits, y)``."""
        if self.parametrization not in _PARAMETRIZATIONS:
            raise ValueError(
                f"parametrization must be one of {_PARAMETRIZATIONS}, got {self.parametrization!r}"
            )
        if int(self.cv) != self.cv or self.cv < 2:
            raise ValueError(f"cv must be an integer >= 2, got {self.cv!r}")
        grid = np.asarray(self.reg_grid, dtype=np.float64)
        if grid.ndim != 1 or grid.size == 0 or np.any(~np.isfinite(grid)) or np.any(grid < 0):
            raise ValueError("reg_grid must be a non-empty sequence of finite penalties >= 0")
        for name in ("reg_lambda", "reg_mu"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0 or None, got {v!r}")
        if int(self.max_iter) != self.max_iter or self.max_iter < 1:
            raise ValueError(f"max_iter must be a positive integer, got {self.max_iter!r}")
        z = self._logits(proba_or_logits)
        n, k = z.shape
        y_idx, cls = class_indices(y, n, self.classes, k)
        kind = self.parametrization
        min_n = self.min_samples
        if min_n is None:
            min_n = {"full": 10 * k, "diagonal": 3 * k, "scalar": 1}[kind]
        self.fallback_ = None
        if kind != "scalar" and (n < min_n or n < 2 * self.cv):
            self.fallback_ = (
                f"{n} fitting samples < {max(min_n, 2 * self.cv)} needed for "
                f"{kind!r}: fitted one temperature instead"
            )
            kind = "scalar"
        # ---- penalty
        self.cv_results_ = {}
        if kind == "scalar":
            lam = mu = 0.0
        elif kind == "full" and self.reg_lambda is not None:
            lam = float(self.reg_lambda)
            mu = lam if self.reg_mu is None else float(self.reg_mu)
        elif kind == "diagonal" and self.reg_mu is not None:
            lam = mu = float(self.reg_mu)
        else:
            folds = fold_indices(y_idx, int(self.cv), self.random_state)
            fixed_mu = None if kind == "diagonal" else self.reg_mu
            scores = {}
            warm: list[np.ndarray | None] = [None] * len(folds)
            for r in sorted(grid.tolist(), reverse=True):  # strong to weak penalty
                m = r if fixed_mu is None else float(fixed_mu)
                losses = []
                for i, f in enumerate(folds):
                    train = np.setdiff1d(np.arange(n), f)
                    theta, _ = self._solve(z[train], y_idx[train], kind, r, m, warm[i])
                    warm[i] = theta
                    losses.append(self._nll(theta, z[f], y_idx[f], kind) * f.size)
                scores[r] = float(np.sum(losses) / n)
            self.cv_results_ = scores
            best = min(scores.values())
            lam = max(r for r, s in scores.items() if s <= best + LOG_LOSS_RTOL * abs(best))
            mu = lam if fixed_mu is None else float(fixed_mu)
        theta, ok = self._solve(z, y_idx, kind, lam, mu)
        w, b = self._unpack(theta, self._basis(k, kind), k)
        self.coef_ = np.array(w)
        self.intercept_ = np.array(b)
        self.reg_lambda_ = lam if kind == "full" else 0.0
        self.reg_mu_ = mu
        self.parametrization_ = kind
        self.converged_ = ok
        self.classes_ = cls
        rows = np.arange(n)
        self.nll_before_ = float(-np.mean(log_softmax(z)[rows, y_idx]))
        self.nll_after_ = self._nll(theta, z, y_idx, kind)
        self.n_samples_ = int(n)
        return self

    def transform(self, proba_or_logits: Any) -> np.ndarray:
        """Recalibrated probabilities ``softmax(W log(p) + b)``; rows sum to 1."""
        if not hasattr(self, "coef_"):
            raise ValueError("DirichletScaler is not fitted; call fit first")
        z = self._logits(proba_or_logits)
        if z.shape[1] != len(self.classes_):
            raise ValueError(f"expected {len(self.classes_)} columns, got {z.shape[1]}")
        return np.exp(log_softmax(z @ self.coef_.T + self.intercept_))

    def fit_transform(self, proba_or_logits: Any, y: Any) -> np.ndarray:
        """``fit`` then ``transform`` on the same data."""
        return self.fit(proba_or_logits, y).transform(proba_or_logits)

    def __repr__(self) -> str:
        fitted = f", reg_lambda_={self.reg_lambda_:.3g}" if hasattr(self, "coef_") else ""
        return f"DirichletScaler(parametrization={self.parametrization!r}{fitted})"
