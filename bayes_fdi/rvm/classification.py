r"""Relevance Vector Classification (Tipping 2001), the paper's section 4.1.

Binary model: :math:`P(t = 1 \mid x) = \sigma(\phi(x)^\top w)` with the RVM's sparse prior
:math:`w_i \sim N(0, \alpha_i^{-1})`.  For fixed :math:`\alpha` the weight posterior is
replaced by its Laplace approximation -- the mode by Newton/IRLS (paper eqs. 26-27) and
:math:`\Sigma = (\Phi^\top B \Phi + A)^{-1}` (eq. 28) -- and :math:`\alpha` maximises the
Laplace evidence, by the fast sequential algorithm (``method="fast"``) or by the
re-estimation :math:`\alpha_i = \gamma_i / \mu_i^2` (``method="em"``, eq. 29).

Probabilities use MacKay's moderated output
:math:`p = \sigma(\kappa\, \mu_a)`, :math:`\kappa = (1 + \pi\sigma_a^2/8)^{-1/2}` with the
latent mean :math:`\mu_a = \phi^\top\mu` and variance :math:`\sigma_a^2 = \phi^\top\Sigma\phi`
(``moderated=True``), or the plain :math:`\sigma(\mu_a)` of eq. 30.  More than two classes
are handled one-vs-rest with normalised probabilities.

Imports :mod:`~bayes_fdi.rvm.base`, :mod:`~bayes_fdi.rvm.kernels`, :mod:`~bayes_fdi.rvm.threads`,
:mod:`~bayes_fdi.rvm.width` and the solvers' face :mod:`bayes_fdi.rvm.sbl`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from sklearn.base import ClassifierMixin
from sklearn.metrics import accuracy_score
from sklearn.utils.multiclass import check_classification_targets
from torch import Tensor

from bayes_fdi.rvm.base import RVMBase, is_torch
from bayes_fdi.rvm.kernels import RBF, Kernel
from bayes_fdi.rvm.sbl import DEFAULT_MAX_BYTES, SBLResult, em_bernoulli, fast_bernoulli
from bayes_fdi.rvm.threads import limit_fit_threads
from bayes_fdi.rvm.width import search_width, width_bounds

__all__ = ["RVC"]


def _plain(value: Any) -> Any:
    """A numpy scalar as the Python value it holds (messages show 'f1', not np.str_('f1'))."""
    return value.item() if isinstance(value, np.generic) else value


class RVC(ClassifierMixin, RVMBase):
    """Relevance Vector Classifier with a scikit-learn API, computed in torch.

    Parameters
    ----------
    kernel, width, method, bias, max_iter, tol, degree, coef0, dtype, device, \
max_kernel_bytes, random_state
        As in :class:`~bayes_fdi.rvm.RVR` (``width="auto"`` maximises the Laplace evidence,
        summed over the one-vs-rest problems when there are more than two classes).
    moderated : bool, default True
        Use MacKay's moderated output ``sigmoid(kappa * mean)`` for probabilities (and
        decision values); ``False``: ``sigmoid(mean)``.

    Attributes
    ----------
    classes_ : ndarray of shape (n_classes,)
        Class labels; ``classes_[1]`` is the positive class of a binary problem.
    relevance_vectors_, relevance_indices_, mean_, covariance_, alpha_, coef_, intercept_, \
evidence_trace_, log_evidence_, n_iter_, converged_, width_, n_features_in_
        As in :class:`~bayes_fdi.rvm.RVR` for a binary problem (no ``beta_``: the Bernoulli
        likelihood has no noise parameter; ``log_evidence_`` is the Laplace approximation).
        With more than two classes: ``relevance_indices_`` / ``relevance_vectors_`` are the
        union over classes, ``log_evidence_`` the sum, ``n_iter_`` the maximum, and
        ``mean_``, ``covariance_``, ``alpha_``, ``coef_``, ``intercept_``,
        ``evidence_trace_`` are lists with one entry per class.
    estimators_ : list of RVC
        With more than two classes: the fitted binary one-vs-rest classifiers, in the order
        of ``classes_``.

    Examples
    --------
    >>> import numpy as np
    >>> from bayes_fdi.rvm import RVC
    >>> rng = np.random.default_rng(0)
    >>> X = np.vstack([rng.normal(-1, 1, (100, 2)), rng.normal(1, 1, (100, 2))])
    >>> y = np.repeat([0, 1], 100)
    >>> clf = RVC(width=1.0).fit(X, y)
    >>> proba = clf.predict_proba(X[:3])
    """

    def __init__(
        self,
        kernel: str | Kernel = "rbf",
        width: float | str = 2.0,
        method: str = "fast",
        moderated: bool = True,
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
        self.moderated = moderated

    # ------------------------------------------------------------------ fitting
    def _solve(
        self, X: Tensor, t: Tensor, width: float | None, x_scale: float = 1.0
    ) -> tuple[SBLResult, Kernel | None]:
        design, kern = self._design(X, width, x_scale=x_scale)
        solver = fast_bernoulli if self.method == "fast" else em_bernoulli
        return solver(design, t, max_iter=self._max_iter(), tol=float(self.tol)), kern

    def _targets(self, y_idx: np.ndarray, X: Tensor) -> list[Tensor]:
        """One 0/1 target vector per binary problem (one for 2 classes, else one per class)."""
        n_classes = len(self.classes_)
        columns = [1] if n_classes == 2 else range(n_classes)
        return [torch.tensor(y_idx == c, dtype=X.dtype, device=X.device) for c in columns]

    @limit_fit_threads
    def fit(self, X: Any, y: Any) -> RVC:
        """Fit the classifier by (Laplace) type-II maximum likelihood.

        Parameters
        ----------
        X : array-like or Tensor of shape (n_samples, n_features)
            Training inputs (``n_samples >= 2``, finite).
        y : array-like or Tensor of shape (n_samples,)
            Class labels (at least two distinct classes).

        Returns
        -------
        RVC
            The fitted estimator.
        """
        self._check_params()
        if not isinstance(self.moderated, bool | np.bool_):
            raise ValueError(f"moderated must be True or False, got {self.moderated!r}")
        X, y = self._validate_fit(X, y, classifier=True)
        check_classification_targets(y)
        classes, y_idx = np.unique(y, return_inverse=True)
        if len(classes) < 2:
            raise ValueError(
                f"RVC needs samples of at least 2 classes in the data, but the data contain "
                f"only one class: {_plain(classes[0])!r}"
            )
        self.classes_ = classes
        Xt, x_scale = self._fit_inputs(X)
        targets = self._targets(y_idx, Xt)

        search = None
        if self.width == "auto":
            search = search_width(
                lambda w: sum(self._solve(Xt, t, w)[0].log_evidence for t in targets),
                1.0,
                bounds=width_bounds(Xt),
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

        if len(targets) == 1:
            result, kern = self._solve(Xt, targets[0], width_s, x_scale)
            self._set_state(result, Xt, kern, width, x_scale=x_scale)
            self.estimators_ = None
        else:
            self._fit_one_vs_rest(Xt, targets, width, width_s, x_scale)
        if search is not None:
            self.width_search_ = search._replace(
                width=search.width * x_scale,
                widths=search.widths * x_scale,
                bounds=None
                if search.bounds is None
                else (search.bounds[0] * x_scale, search.bounds[1] * x_scale),
            )
        return self

    def _fit_one_vs_rest(
        self,
        Xt: Tensor,
        targets: list[Tensor],
        width: float | None,
        width_s: float | None,
        x_scale: float,
    ) -> None:
        subs = []
        for t in targets:
            sub = type(self)(**self.get_params())
            sub.classes_ = np.array([0, 1])
            sub.n_features_in_ = self.n_features_in_
            result, kern = sub._solve(Xt, t, width_s, x_scale)
            sub._set_state(result, Xt, kern, width, x_scale=x_scale)
            sub.estimators_ = None
            subs.append(sub)
        self._adopt_one_vs_rest(subs, Xt, width)

    def _adopt_one_vs_rest(self, subs: list[RVC], Xt: Tensor | None, width: float | None) -> None:
        """Summarise fitted one-vs-rest sub-classifiers as this estimator's attributes."""
        self.estimators_ = subs
        idx = np.unique(np.concatenate([s.relevance_indices_ for s in subs]))
        self.relevance_indices_ = idx
        if subs[0]._kernel_ is None:
            self.relevance_vectors_ = np.empty((len(idx), 0))
        else:
            rv = {
                int(i): v
                for s in subs
                for i, v in zip(s.relevance_indices_, s.relevance_vectors_, strict=True)
            }
            self.relevance_vectors_ = np.array([rv[int(i)] for i in idx]).reshape(
                len(idx), self.n_features_in_
            )
        self.mean_ = [s.mean_ for s in subs]
        self.covariance_ = [s.covariance_ for s in subs]
        self.alpha_ = [s.alpha_ for s in subs]
        self.coef_ = [s.coef_ for s in subs]
        self.intercept_ = [s.intercept_ for s in subs]
        self.evidence_trace_ = [s.evidence_trace_ for s in subs]
        self.log_evidence_ = float(sum(s.log_evidence_ for s in subs))
        self.n_iter_ = max(s.n_iter_ for s in subs)
        self.converged_ = all(s.converged_ for s in subs)
        self.width_ = width
        self._dtype_ = subs[0]._dtype_
        self._device_ = subs[0]._device_
        self._kernel_ = subs[0]._kernel_
        self._X_fit_ = subs[0]._X_fit_ if Xt is None else Xt
        self._x_scale_ = subs[0]._x_scale_
        self._t_scale_ = 1.0

    # ------------------------------------------------------------------ prediction
    def _latent_tensor(self, Xt: Tensor) -> tuple[Tensor, Tensor]:
        """Latent mean and variance of a binary (sub-)model at tensor inputs."""
        Phi = self._phi(Xt)
        mean = Phi @ self._mu_
        var = ((Phi @ self._Sigma_) * Phi).sum(1).clamp_min(0.0)
        return mean, var

    def _logits(self, Xt: Tensor) -> Tensor:
        """Log-odds used for probabilities: (n,) binary, (n, C) one-vs-rest."""
        models = [self] if self.estimators_ is None else self.estimators_
        cols = []
        for m in models:
            mean, var = m._latent_tensor(Xt)
            cols.append(mean / torch.sqrt(1.0 + math.pi * var / 8.0) if self.moderated else mean)
        return cols[0] if self.estimators_ is None else torch.stack(cols, dim=1)

    def predict_latent(self, X: Any) -> tuple[Any, Any]:
        """Mean and standard deviation of the latent ``a = phi(x)^T w`` (binary problems).

        Returns
        -------
        mean, std : ndarray or Tensor of shape (n,)
            With more than two classes: shape ``(n, n_classes)`` (one-vs-rest latents).
        """
        Xt = self._inputs(X)
        models = [self] if self.estimators_ is None else self.estimators_
        pairs = [m._latent_tensor(Xt) for m in models]
        if self.estimators_ is None:
            mean, var = pairs[0]
        else:
            mean = torch.stack([p[0] for p in pairs], 1)
            var = torch.stack([p[1] for p in pairs], 1)
        return self._output(mean, X), self._output(var.sqrt(), X)

    def decision_function(self, X: Any) -> Any:
        """Log-odds behind :meth:`predict_proba` (moderated when ``moderated=True``).

        Returns
        -------
        ndarray or Tensor
            Shape ``(n,)`` for two classes (positive: ``classes_[1]``), else
            ``(n, n_classes)`` one-vs-rest log-odds.
        """
        Xt = self._inputs(X)
        return self._output(self._logits(Xt), X)

    def _proba_tensor(self, Xt: Tensor) -> Tensor:
        z = self._logits(Xt)
        if self.estimators_ is None:
            p1 = torch.sigmoid(z)
            return torch.stack([1.0 - p1, p1], dim=1)
        # p_k proportional to sigmoid(z_k), normalised in log space: identical in exact
        # arithmetic, and no 0/0 when every sigmoid underflows (all z_k << 0)
        return torch.softmax(torch.nn.functional.logsigmoid(z), dim=1)

    def predict_proba(self, X: Any) -> Any:
        """Class probabilities, columns in the order of ``classes_``.

        Returns
        -------
        ndarray or Tensor of shape (n, n_classes)
        """
        Xt = self._inputs(X)
        return self._output(self._proba_tensor(Xt), X)

    def predict(self, X: Any) -> Any:
        """Most probable class labels.

        Returns
        -------
        ndarray of shape (n,)
            Labels from ``classes_`` (a tensor of class indices mapped to labels when the
            input is a tensor and the labels are numeric).
        """
        Xt = self._inputs(X)
        idx = self._proba_tensor(Xt).argmax(1).cpu().numpy()
        labels = self.classes_[idx]
        if is_torch(X) and np.issubdtype(labels.dtype, np.number):
            return torch.as_tensor(labels, device=X.device)
        return labels

    def score(self, X: Any, y: Any, sample_weight: Any = None) -> float:
        """Mean accuracy (torch inputs accepted)."""
        pred = self.predict(X)
        if is_torch(pred):
            pred = pred.cpu().numpy()
        y_np = y.detach().cpu().numpy() if is_torch(y) else y
        return float(accuracy_score(y_np, pred, sample_weight=sample_weight))
