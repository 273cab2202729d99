"""Shared machinery of :class:`~bayes_fdi.rvm.RVR` and :class:`~bayes_fdi.rvm.RVC`.

Input validation (numpy via scikit-learn, torch natively), kernel resolution, the
candidate basis, fitted-state bookkeeping and the design matrix of new inputs.

Scale invariance. The fit is computed on rescaled data whenever the data lie far from unit
scale, in a way that is exact in real arithmetic: with an RBF kernel the inputs are divided by a
power of two ``x_scale`` and the width with them (``k(x/c, z/c; sigma/c) = k(x, z; sigma)``, so
the design matrix is unchanged), with a linear or polynomial kernel the inputs are divided by
a power of two and the kernel follows them (`bayes_fdi.rvm.rescaling`: its columns change by one
power of two, which the solvers' unit-norm columns absorb); for regression the targets are
divided by a power of two
``t_scale`` (the sparse Bayesian model is scale-equivariant: weights scale with ``t``,
precisions with ``t^-2``, the log evidence shifts by ``-N log t_scale``). Dividing by a power of
two loses nothing, so any finite data from ``1e-300`` to ``1e300`` fit; data within
``[2^-32, 2^32]`` are not rescaled at all (``x_scale = t_scale = 1``). The fitted state is kept
in the scaled units (``_mu_``, ``_Sigma_``, ``_X_fit_``, ``_kernel_``; the scales in
``_x_scale_`` and ``_t_scale_``) and the public attributes are given in the caller's units.

Imports :mod:`~bayes_fdi.rvm.kernels`, :mod:`~bayes_fdi.rvm.rescaling`,
:mod:`~bayes_fdi.rvm.persistence` and the solvers' face
:mod:`bayes_fdi.rvm.sbl`.
"""

from __future__ import annotations

import math
import warnings
from numbers import Integral, Real
from typing import Any

import numpy as np
import torch
from sklearn.base import BaseEstimator
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils.validation import check_is_fitted, validate_data
from torch import Tensor

from bayes_fdi.rvm.kernels import RBF, Kernel, Linear, Polynomial
from bayes_fdi.rvm.persistence import save
from bayes_fdi.rvm.rescaling import (
    MAX_SCALED_WIDTH,
    MIN_SCALED_WIDTH,
    check_kernel_range,
    has_offset,
    kernel_factor,
    power_of_two_scale,
    rescaled_kernel,
)
from bayes_fdi.rvm.sbl import DEFAULT_MAX_BYTES, Design, SBLResult

__all__ = ["RVMBase", "is_torch", "power_of_two_scale"]

_DTYPES = {"float64": torch.float64, "float32": torch.float32}
_METHODS = ("fast", "em")


def is_torch(X: Any) -> bool:
    """Whether ``X`` is a torch tensor (the estimators then answer in tensors, else in numpy)."""
    return isinstance(X, Tensor)


class RVMBase(BaseEstimator):
    """Common parameters, validation and fitted state of the RVM estimators.

    Not used directly; see :class:`~bayes_fdi.rvm.RVR` and :class:`~bayes_fdi.rvm.RVC`.
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
    ) -> None:
        self.kernel = kernel
        self.width = width
        self.method = method
        self.bias = bias
        self.max_iter = max_iter
        self.tol = tol
        self.degree = degree
        self.coef0 = coef0
        self.dtype = dtype
        self.device = device
        self.max_kernel_bytes = max_kernel_bytes
        self.random_state = random_state

    # ------------------------------------------------------------------ params
    def _check_params(self) -> None:
        if self.method not in _METHODS:
            raise ValueError(f"method must be one of {_METHODS}, got {self.method!r}")
        if self.dtype not in _DTYPES:
            raise ValueError(f"dtype must be one of {tuple(_DTYPES)}, got {self.dtype!r}")
        if not (isinstance(self.kernel, Kernel) or callable(self.kernel)) and self.kernel not in (
            "rbf",
            "linear",
            "poly",
            "precomputed",
        ):
            raise ValueError(
                "kernel must be 'rbf', 'linear', 'poly', 'precomputed', a Kernel or a callable, "
                f"got {self.kernel!r}"
            )
        if isinstance(self.width, str):
            if self.width != "auto":
                raise ValueError(f"width must be a positive number or 'auto', got {self.width!r}")
            if self.kernel != "rbf":
                raise ValueError("width='auto' needs kernel='rbf'")
        elif (
            not isinstance(self.width, Real)
            or isinstance(self.width, bool)
            or not math.isfinite(self.width)
            or self.width <= 0
        ):
            raise ValueError(f"width must be a positive number or 'auto', got {self.width!r}")
        if self.max_iter is not None and (
            not isinstance(self.max_iter, Integral)
            or isinstance(self.max_iter, bool)
            or self.max_iter < 1
        ):
            raise ValueError(f"max_iter must be a positive integer or None, got {self.max_iter!r}")
        if not isinstance(self.tol, Real) or not self.tol > 0:
            raise ValueError(f"tol must be a positive number, got {self.tol!r}")
        if not isinstance(self.bias, bool | np.bool_):
            raise ValueError(f"bias must be True or False, got {self.bias!r}")

    @property
    def _torch_dtype(self) -> torch.dtype:
        return _DTYPES[self.dtype]

    def _max_iter(self) -> int:
        if self.max_iter is not None:
            return int(self.max_iter)
        return 10000 if self.method == "fast" else 1000

    def _resolve_kernel(self, width: float | None, x_scale: float = 1.0) -> Kernel | None:
        """The kernel object for ``width`` on inputs divided by ``x_scale`` (``None`` for
        ``'precomputed'``).

        An RBF kernel takes the width in rescaled units. On inputs divided by the power of two
        ``s = x_scale``, a linear kernel ``x.z + c`` becomes ``x.z + c / s^2`` and a polynomial
        one ``(gamma x.z + c0)^d`` becomes ``(gamma x.z + c0 / s^2)^d``: the caller's kernel
        divided by ``s^2`` and ``s^(2d)``, so every kernel column differs from the caller's by
        one power of two and the solvers, which work on unit-norm columns, fit the same model.
        """
        if self.kernel == "precomputed":
            return None
        if self._is_plain_rbf():  # at the (rescaled) width
            return RBF(width)
        if self.kernel == "linear":
            return rescaled_kernel(Linear(), x_scale)
        if self.kernel == "poly":
            return rescaled_kernel(Polynomial(self.degree, 1.0, self.coef0), x_scale)
        if type(self.kernel) in (Linear, Polynomial):
            return rescaled_kernel(self.kernel, x_scale)
        if isinstance(self.kernel, Kernel):
            return self.kernel
        return _CallableKernel(self.kernel)

    # ------------------------------------------------------------------ inputs
    def _compute_device(self, X: Any) -> torch.device:
        if self.device is not None:
            return torch.device(self.device)
        if is_torch(X):
            return X.device
        return torch.device("cpu")

    def _validate_torch_X(self, X: Tensor, *, reset: bool, min_samples: int) -> Tensor:
        if X.ndim != 2:
            raise ValueError(
                f"Expected a 2-D tensor X (n_samples, n_features), got shape {tuple(X.shape)}"
            )
        if X.is_complex():
            raise ValueError("Complex data not supported")
        if not (
            X.is_floating_point()
            or X.dtype in (torch.int8, torch.int16, torch.int32, torch.int64, torch.uint8)
        ):
            raise ValueError(f"X must be numeric, got dtype {X.dtype}")
        if X.shape[0] < min_samples:
            raise ValueError(
                f"Found array with {X.shape[0]} sample(s) (shape={tuple(X.shape)}) while a "
                f"minimum of {min_samples} is required."
            )
        if X.shape[1] < 1:
            raise ValueError(f"X has 0 features (shape={tuple(X.shape)}); at least 1 is required.")
        if X.is_floating_point() and not bool(torch.isfinite(X).all()):
            raise ValueError("Input X contains NaN or infinity.")
        if reset:
            self.n_features_in_ = int(X.shape[1])
        elif X.shape[1] != self.n_features_in_:
            raise ValueError(
                f"X has {X.shape[1]} features, but {type(self).__name__} is expecting "
                f"{self.n_features_in_} features as input."
            )
        return X

    def _validate_fit(self, X: Any, y: Any, *, classifier: bool) -> tuple[Any, Any]:
        """Validate training data; returns ``(X, y)`` as (numpy or torch) arrays."""
        if is_torch(X):
            self._validate_torch_X(X, reset=True, min_samples=2)
            if y is None:
                raise ValueError(
                    f"{type(self).__name__} requires y to be passed, but the target y is None."
                )
            y_np = y.detach().cpu().numpy() if is_torch(y) else np.asarray(y)
            if y_np.ndim == 2 and y_np.shape[1] == 1:
                y_np = y_np[:, 0]
            if y_np.ndim != 1:
                raise ValueError(f"y must be 1-D, got shape {y_np.shape}")
            if y_np.shape[0] != X.shape[0]:
                raise ValueError(
                    f"X and y have inconsistent numbers of samples: {X.shape[0]} != {y_np.shape[0]}"
                )
            if not classifier:
                y_np = np.asarray(y_np, dtype=np.float64)
                if not np.all(np.isfinite(y_np)):
                    raise ValueError("Input y contains NaN or infinity.")
            if hasattr(self, "feature_names_in_"):
                del self.feature_names_in_
            return X, y_np
        X, y = validate_data(
            self,
            X,
            y,
            dtype=[np.float64, np.float32],
            ensure_min_samples=2,
            y_numeric=not classifier,
        )
        return X, y

    def _validate_predict(self, X: Any) -> Any:
        check_is_fitted(self)
        if is_torch(X):
            return self._validate_torch_X(X, reset=False, min_samples=1)
        return validate_data(self, X, reset=False, dtype=[np.float64, np.float32])

    def _to_tensor(self, X: Any, *, fitting: bool = False) -> Tensor:
        """Inputs as a tensor in the model's dtype and on its compute device."""
        if fitting:
            dtype, dev = self._torch_dtype, self._compute_device(X)
        else:
            dtype, dev = self._dtype_, self._device_
        if is_torch(X):
            # a copy: the model must not share memory with (and change with) the caller's tensor
            return X.detach().to(dtype=dtype, device=dev, copy=True)
        out = torch.tensor(np.asarray(X), dtype=dtype, device=dev)
        if fitting and not bool(torch.isfinite(out).all()):
            raise ValueError(
                f"X does not fit in {self.dtype}: its magnitudes overflow to infinity (largest "
                f"{float(np.abs(np.asarray(X, dtype=np.float64)).max()):.3g}); use dtype='float64'"
            )
        return out

    def _kernel_factor(self, x_scale: float) -> float:
        """The caller's kernel over the rescaled one on inputs divided by ``x_scale``
        (`~bayes_fdi.rvm.rescaling.kernel_factor`; 1 for an RBF kernel)."""
        if x_scale == 1.0 or self._is_plain_rbf():
            return 1.0
        return kernel_factor(self._resolve_kernel(None), x_scale)

    def _is_plain_rbf(self) -> bool:
        """Whether the kernel is the RBF kernel (by name or as a plain `RBF` object)."""
        return self.kernel == "rbf" or type(self.kernel) is RBF

    def _scales_inputs(self) -> bool:
        """Whether the kernel lets the inputs be rescaled exactly: a plain RBF, linear or
        polynomial kernel (see `_resolve_kernel`)."""
        builtin = ("rbf", "linear", "poly")
        return self.kernel in builtin or type(self.kernel) in (RBF, Linear, Polynomial)

    def _fit_inputs(self, X: Any) -> tuple[Tensor, float]:
        """Training inputs as a (copied) tensor, divided by their power-of-two scale."""
        Xt = self._to_tensor(X, fitting=True)
        x_scale = power_of_two_scale(Xt) if self._scales_inputs() else 1.0
        if x_scale < 1.0 and not self._is_plain_rbf() and has_offset(self._resolve_kernel(None)):
            x_scale = 1.0  # tiny inputs of a kernel with an offset stay (`has_offset`)
        if x_scale != 1.0:
            Xt = Xt / x_scale
        return Xt, x_scale

    def _inputs(self, X: Any) -> Tensor:
        """Validated new inputs as a tensor in the model's (rescaled) input units."""
        Xt = self._to_tensor(self._validate_predict(X))
        scale = getattr(self, "_x_scale_", 1.0)
        return Xt / scale if scale != 1.0 else Xt

    def _scaled_width(self, width: float | None, x_scale: float) -> float | None:
        """The RBF width in rescaled input units (``None`` stays ``None``)."""
        if width is None:
            return width
        return min(max(width / x_scale, MIN_SCALED_WIDTH), MAX_SCALED_WIDTH)

    @staticmethod
    def _output(value: Tensor, like: Any) -> Any:
        """numpy in -> numpy out; torch in -> torch out on the input's device."""
        if is_torch(like):
            return value.to(like.device)
        return value.detach().cpu().numpy()

    # ------------------------------------------------------------------ design
    def _design(
        self, X: Tensor, width: float | None, rhs: Tensor | None = None, x_scale: float = 1.0
    ) -> tuple[Design, Kernel | None]:
        kern = self._resolve_kernel(width, x_scale)
        if kern is None:
            return Design(matrix=X, bias=self.bias), None
        check_kernel_range(kern, X, x_scale=x_scale, shown=lambda: self._resolve_kernel(width))
        design = Design(kernel=kern, X=X, bias=self.bias, max_bytes=self.max_kernel_bytes, rhs=rhs)
        return design, kern

    def _set_state(
        self,
        result: SBLResult,
        X: Tensor,
        kern: Kernel | None,
        width: float | None,
        *,
        warn: bool = True,
        x_scale: float = 1.0,
        t_scale: float = 1.0,
    ) -> None:
        """Store a solver result as the fitted state (torch internals, numpy attributes).

        ``result``, ``X`` and ``kern`` are in rescaled units (inputs / ``x_scale``, targets /
        ``t_scale``); ``width`` is the RBF width in the caller's units. The public attributes
        are converted to the caller's units.
        """
        mean_t, cov_t, alpha_t = result.mean, result.covariance, result.alpha
        if not (
            bool(torch.isfinite(mean_t).all())
            and bool(torch.isfinite(cov_t).all())
            and bool(torch.isfinite(alpha_t).all())
            and bool((alpha_t > 0).all())
        ):
            raise ValueError(
                f"{type(self).__name__}: the fit produced non-finite weights or precisions; "
                "the problem is numerically degenerate for this kernel and width"
            )
        if warn and not result.converged:
            warnings.warn(
                f"{type(self).__name__} (method={self.method!r}) did not converge in "
                f"{result.n_iter} iterations; increase max_iter or tol",
                ConvergenceWarning,
                stacklevel=3,
            )
        offset = 1 if self.bias else 0
        active = result.active
        has_bias = bool(self.bias) and bool((active == 0).any())
        feat = active[active >= offset] - offset
        self._dtype_ = X.dtype
        self._device_ = X.device
        self._kernel_ = kern
        self._X_fit_ = X
        self._x_scale_ = float(x_scale)
        self._t_scale_ = float(t_scale)
        self._active_ = active
        self._feat_ = feat
        self._has_bias_ = has_bias
        self._rv_ = X[feat] if kern is not None else None
        self._mu_ = result.mean.to(X.dtype)
        self._Sigma_ = result.covariance.to(X.dtype)
        self._result_ = result
        self.relevance_indices_ = feat.cpu().numpy()
        self.relevance_vectors_ = (
            (self._rv_ * x_scale).cpu().numpy()
            if self._rv_ is not None
            else np.empty((feat.numel(), 0))
        )
        # kernel columns in the caller's units: the rescaled kernel times `_kernel_factor`
        per_column = np.where(
            np.arange(active.numel()) < int(has_bias), 1.0, self._kernel_factor(x_scale)
        )
        with np.errstate(over="ignore", under="ignore", invalid="ignore"):
            mean = result.mean.cpu().numpy() * t_scale / per_column
            cov = result.covariance.cpu().numpy() * (t_scale * t_scale)
            self.covariance_ = cov / np.multiply.outer(per_column, per_column)
            self.alpha_ = result.alpha.cpu().numpy() / (t_scale * t_scale) * per_column**2
        shift = X.shape[0] * math.log(t_scale)
        self.mean_ = mean
        self.coef_ = mean[1:] if has_bias else mean
        self.intercept_ = float(mean[0]) if has_bias else 0.0
        self.evidence_trace_ = result.evidence_trace.cpu().numpy() - shift
        self.log_evidence_ = float(result.log_evidence) - shift
        self.n_iter_ = int(result.n_iter)
        self.converged_ = bool(result.converged)
        self.width_ = width

    def _phi(self, X: Tensor) -> Tensor:
        """Active-basis design matrix of validated tensor inputs."""
        parts = []
        if self._has_bias_:
            parts.append(torch.ones(X.shape[0], 1, dtype=X.dtype, device=X.device))
        if self._feat_.numel():
            if self._kernel_ is None:
                parts.append(X[:, self._feat_.to(X.device)])
            else:
                scale = getattr(self, "_x_scale_", 1.0)
                check_kernel_range(
                    self._kernel_,
                    X,
                    x_scale=scale,
                    shown=lambda: self._resolve_kernel(self.width_, 1.0),
                )
                parts.append(self._kernel_(X, self._rv_))
        if not parts:
            return torch.zeros(X.shape[0], 0, dtype=X.dtype, device=X.device)
        return torch.cat(parts, dim=1)

    def design_matrix(self, X: Any, basis: str = "active") -> Tensor:
        """The design matrix of ``X`` in the model's dtype and device.

        Parameters
        ----------
        X : array-like or Tensor of shape (n, d)
            Inputs (for ``kernel='precomputed'``: the design columns themselves).
        basis : {"active", "all"}
            ``"active"``: the relevance basis (bias column first if active), matching
            ``mean_``; ``"all"``: every candidate (bias column first if ``bias``, then one
            column per training row / precomputed column).

        Returns
        -------
        Tensor
            ``(n, M)`` design matrix.
        """
        check_is_fitted(self)
        if basis not in ("active", "all"):
            raise ValueError(f"basis must be 'active' or 'all', got {basis!r}")
        if basis == "active" and getattr(self, "estimators_", None):
            raise ValueError(
                "a one-vs-rest model has one active basis per class: use "
                "estimators_[k].design_matrix(X) or basis='all'"
            )
        Xt = self._inputs(X)
        if basis == "active":
            return self._in_caller_units(self._phi(Xt), int(self._has_bias_))
        parts = []
        if self.bias:
            parts.append(torch.ones(Xt.shape[0], 1, dtype=Xt.dtype, device=Xt.device))
        parts.append(Xt if self._kernel_ is None else self._kernel_(Xt, self._X_fit_))
        return self._in_caller_units(torch.cat(parts, dim=1), int(self.bias))

    def _in_caller_units(self, Phi: Tensor, n_bias: int) -> Tensor:
        """Design columns of the rescaled kernel in the caller's kernel units (the first
        ``n_bias`` columns are the bias)."""
        factor = self._kernel_factor(getattr(self, "_x_scale_", 1.0))
        if factor == 1.0 or Phi.shape[1] == n_bias:
            return Phi
        return torch.cat([Phi[:, :n_bias], Phi[:, n_bias:] * factor], dim=1)

    def fit_posterior(self, X: Any, y: Any, **kwargs: Any) -> Any:
        """Full Bayesian posterior of the weights (Pyro NUTS or SVI) on the fitted basis.

        A thin forwarder to :func:`bayes_fdi.rvm.posterior.fit_posterior` (imported lazily);
        see that function for the keyword arguments (``inference="nuts"|"svi"``,
        ``num_samples``, ``warmup_steps``, ``seed``, ``basis="active"|"all"``).

        Returns
        -------
        object
            A posterior with ``.predict(X, return_std=True)`` and ``.to_arviz()``.
        """
        from bayes_fdi.rvm.posterior import fit_posterior

        return fit_posterior(self, X, y, **kwargs)

    def save(self, path: Any) -> None:
        """Save the fitted model to ``path`` (``.npz`` arrays + JSON metadata, no pickle).

        See :func:`bayes_fdi.rvm.persistence.save`.
        """
        save(self, path)


class _CallableKernel(Kernel):
    """Wrap a user callable ``f(X, Z) -> matrix`` as a :class:`Kernel` (not serialisable)."""

    def __init__(self, func: Any) -> None:
        self.func = func

    def forward(self, X: Tensor, Z: Tensor) -> Tensor:
        out = self.func(X, Z)
        return torch.as_tensor(out, dtype=X.dtype, device=X.device)

    def to_dict(self) -> dict[str, Any]:
        raise ValueError("a model with a user-supplied callable kernel cannot be saved")
