"""The entry points: :func:`sample_posterior` (a model on an explicit design matrix) and
:func:`fit_posterior` (a fitted ``RVR`` / ``RVC``), both returning an immutable result.
"""

from __future__ import annotations

import copy
import functools
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
import torch
from sklearn.exceptions import ConvergenceWarning

from bayes_fdi.rvm.posterior.classification_model import SparseBayesClassificationModel
from bayes_fdi.rvm.posterior.diagnostics import PosteriorDiagnostics
from bayes_fdi.rvm.posterior.hyperpriors import Hyperpriors
from bayes_fdi.rvm.posterior.numpy_bridge import DTYPE
from bayes_fdi.rvm.posterior.regression_model import SparseBayesRegressionModel
from bayes_fdi.rvm.posterior.results import OneVsRestPosterior, RVMPosterior
from bayes_fdi.rvm.posterior.samplers import (
    Model,
    chain_seeds,
    check_init,
    check_int,
    run_nuts,
    run_svi,
)

__all__ = ["fit_posterior", "sample_posterior"]


def sample_posterior(
    model: Model,
    *,
    inference: Literal["nuts", "svi"] = "nuts",
    num_samples: int = 500,
    warmup_steps: int = 500,
    num_chains: int = 2,
    seed: int = 0,
    init: Mapping[str, Any] | None = None,
    target_accept_prob: float = 0.9,
    max_tree_depth: int = 10,
    full_mass: bool = False,
    init_jitter: float = 0.1,
    svi_steps: int = 2000,
    svi_lr: float = 0.03,
    svi_particles: int = 4,
    svi_jit: bool = True,
    progress: bool = False,
    basis: str = "design",
    basis_names: Sequence[str] | None = None,
    design: Callable[[Any], Any] | None = None,
    classes: Any = None,
) -> RVMPosterior:
    """Sample the posterior of a :class:`SparseBayesRegressionModel` / ``ClassificationModel``.

    Parameters
    ----------
    model : SparseBayesRegressionModel or SparseBayesClassificationModel
    inference : {"nuts", "svi"}
        ``"nuts"``: regression samples ``(log alpha, log beta)`` of the collapsed model, then draws
        the weights exactly given each draw; classification samples ``(log alpha, z)``.
        ``"svi"``: full-rank Gaussian guide on the non-centred model (``w = z / sqrt(alpha)``),
        ``num_samples * num_chains`` independent draws from it.
    num_samples, warmup_steps, num_chains : int
        Kept draws and warm-up iterations per chain; chains run one after another.
    seed : int
        Seeds every chain (via ``numpy.random.SeedSequence``), the weight draws and SVI.
    init : dict, optional
        Start values: ``log_alpha`` and ``log_beta`` (regression) or weights ``w`` (or ``z``)
        (classification); default ``model.default_init()``.
        Each chain starts at ``init`` plus ``N(0, init_jitter^2)`` noise.
    target_accept_prob, max_tree_depth, full_mass : NUTS settings.
    svi_steps, svi_lr, svi_particles, svi_jit : SVI settings (ClippedAdam with a learning rate
        decaying 20x; ``svi_particles`` vectorised ELBO particles; ``svi_jit`` traces the ELBO
        with ``JitTrace_ELBO``, about 2x faster).
    progress : bool
        Show progress bars / ELBO.
    basis, basis_names, design, classes
        Recorded on the result; ``design`` maps inputs to design matrices for ``predict``.

    Returns
    -------
    RVMPosterior
    """
    if inference not in ("nuts", "svi"):
        raise ValueError(f"inference must be 'nuts' or 'svi', got {inference!r}")
    num_samples = check_int("num_samples", num_samples, 4)
    warmup_steps = check_int("warmup_steps", warmup_steps, 0)
    num_chains = check_int("num_chains", num_chains, 1)
    seed = check_int("seed", seed, 0)
    if not 0.0 < target_accept_prob < 1.0:
        raise ValueError(f"target_accept_prob must be in (0, 1), got {target_accept_prob!r}")
    start = check_init(model, init)
    m = model.n_basis
    names = tuple(basis_names) if basis_names is not None else tuple(f"b{i}" for i in range(m))
    if len(names) != m:
        raise ValueError(f"basis_names has {len(names)} entries for {m} basis functions")

    t0 = time.perf_counter()
    if inference == "nuts":
        log_alpha, log_beta, weights, diagnostics = _nuts_draws(
            model,
            start,
            t0,
            num_samples=num_samples,
            warmup_steps=warmup_steps,
            num_chains=num_chains,
            seed=seed,
            target_accept_prob=target_accept_prob,
            max_tree_depth=check_int("max_tree_depth", max_tree_depth, 1),
            full_mass=bool(full_mass),
            init_jitter=float(init_jitter),
            progress=progress,
        )
    else:
        log_alpha, log_beta, weights, diagnostics = _svi_draws(
            model,
            start,
            t0,
            steps=check_int("svi_steps", svi_steps, 1),
            lr=float(svi_lr),
            particles=check_int("svi_particles", svi_particles, 1),
            num_draws=num_samples * num_chains,
            seed=seed,
            jit=bool(svi_jit),
            progress=progress,
        )
    return RVMPosterior(
        kind=model.kind,
        inference=inference,
        basis=basis,
        log_alpha=log_alpha,
        log_beta=log_beta,
        weights=weights,
        diagnostics=diagnostics,
        hyperpriors=model.hyperpriors,
        basis_names=names,
        classes=None if classes is None else np.asarray(classes),
        design=design,
        train_design=model.Phi.numpy(),
        observed=model.t.numpy(),
    )


def _nuts_draws(
    model: Model, start: dict[str, torch.Tensor], t0: float, **settings: Any
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, PosteriorDiagnostics]:
    """NUTS chains (``settings`` as :func:`~bayes_fdi.rvm.posterior.samplers.run_nuts` takes
    them), the weights of each draw (drawn exactly given it for regression, mapped from the
    latent for classification) and the diagnostics (wall time since ``t0``); warns when the
    chains may not have converged.

    Returns
    -------
    log_alpha, log_beta, weights : numpy.ndarray
        ``log_beta`` is None for classification.
    diagnostics : PosteriorDiagnostics
    """
    raw, st = run_nuts(model, start, **settings)
    seed, num_chains, m = settings["seed"], settings["num_chains"], model.n_basis
    log_alpha = raw["log_alpha"]
    if model.kind == "regression":
        log_beta = raw["log_beta"]
        gen = torch.Generator().manual_seed(chain_seeds(seed, num_chains + 1)[-1])
        w = model.sample_weights(
            torch.as_tensor(log_alpha.reshape(-1, m)),
            torch.as_tensor(log_beta.reshape(-1)),
            generator=gen,
        )
        weights = w.numpy().reshape(log_alpha.shape)
    else:
        log_beta = None
        weights = model.weights_from_latent(log_alpha, raw["v"])
    elapsed = time.perf_counter() - t0
    variables = {"log_alpha": log_alpha, "weights": weights}
    if log_beta is not None:
        variables["log_beta"] = log_beta
    diagnostics = PosteriorDiagnostics.from_nuts(variables, st, elapsed)
    bad_r_hat = num_chains > 1 and diagnostics.max_r_hat > 1.01
    if bad_r_hat or diagnostics.n_divergences:
        warnings.warn(
            f"NUTS chains may not have converged ({diagnostics}); check "
            "posterior.diagnostics, run longer or with more chains (R-hat < 1.01 needs a bulk "
            "ESS of several hundred per chain; 4 chains are recommended). Large R-hat with "
            "many overlapping basis functions usually means a multimodal posterior (chains "
            "switch on different subsets of similar basis functions).",
            ConvergenceWarning,
            stacklevel=3,
        )
    return log_alpha, log_beta, weights, diagnostics


def _svi_draws(
    model: Model, start: dict[str, torch.Tensor], t0: float, **settings: Any
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, PosteriorDiagnostics]:
    """Draws from the SVI guide (``settings`` as
    :func:`~bayes_fdi.rvm.posterior.samplers.run_svi` takes them) and the diagnostics (wall
    time since ``t0``), in the order of :func:`_nuts_draws`."""
    raw, elbo = run_svi(model, start, **settings)
    diagnostics = PosteriorDiagnostics(
        inference="svi", elbo=elbo, wall_time_s=time.perf_counter() - t0
    )
    return raw["log_alpha"], raw.get("log_beta"), raw["weights"], diagnostics


def _estimator_init(
    estimator: Any, model: Model, basis: str
) -> tuple[dict[str, torch.Tensor], tuple[str, ...]]:
    """Start values and basis names from a fitted RVR / RVC (type-II ML point estimates).

    Column layout (RVM API): ``"active"`` = bias (if kept) then the relevance columns;
    ``"all"`` = bias (if the estimator has ``bias=True``) then every candidate column, so the
    relevance column ``i`` of ``relevance_indices_`` sits at ``offset + i``.
    """
    alpha = np.asarray(estimator.alpha_, dtype=np.float64).reshape(-1)
    rv = np.asarray(estimator.relevance_indices_).reshape(-1).astype(int)
    has_bias = alpha.size == rv.size + 1
    if not np.all(np.isfinite(alpha)) or np.any(alpha <= 0):
        raise ValueError("estimator.alpha_ must be positive and finite over the active basis")
    m = model.n_basis
    if basis == "active":
        if m != alpha.size:
            raise ValueError(f"design matrix has {m} columns but estimator.alpha_ has {alpha.size}")
        cols = np.arange(m)
        names = (("bias",) if has_bias else ()) + tuple(f"rv{i}" for i in rv)
        log_alpha = np.log(alpha)
    else:
        offset = 1 if bool(getattr(estimator, "bias", has_bias)) else 0
        names = (("bias",) if offset else ()) + tuple(f"c{i}" for i in range(m - offset))
        cols = np.concatenate([[0] if has_bias else [], rv + offset]).astype(int)
        if cols.size != alpha.size or (cols.size and cols.max() >= m):
            raise ValueError("estimator's active basis does not fit its basis='all' design matrix")
        # inactive basis functions start where the alpha hyperprior begins to bite (weight ~ 0)
        log_alpha = np.full(m, math.log(0.1 / model.hyperpriors.b_alpha))
        log_alpha[cols] = np.log(alpha)
    init = {"log_alpha": torch.as_tensor(log_alpha, dtype=DTYPE)}
    if model.kind == "regression":
        beta = float(np.asarray(estimator.beta_))
        if not (math.isfinite(beta) and beta > 0):
            raise ValueError(f"estimator.beta_ must be positive and finite, got {beta!r}")
        init["log_beta"] = torch.tensor(math.log(beta), dtype=DTYPE)
    else:
        w = np.zeros(m)
        mean = np.asarray(estimator.mean_, dtype=np.float64).reshape(-1)
        if mean.size != cols.size:
            raise ValueError("estimator.mean_ does not match estimator.alpha_")
        w[cols] = mean
        init["w"] = torch.as_tensor(w, dtype=DTYPE)
    return init, names


def _well_determined_from_estimator(estimator: Any, basis: str, m: int) -> Any:
    """Per-basis centring mask from the type-II fit (``|mean_i| > 3 sd_i``), or "auto"."""
    cov = getattr(estimator, "covariance_", None)
    mean = getattr(estimator, "mean_", None)
    if basis != "active" or cov is None or mean is None:
        return "auto"
    cov = np.asarray(cov, dtype=np.float64)
    mean = np.asarray(mean, dtype=np.float64).reshape(-1)
    if cov.shape != (m, m) or mean.size != m:
        return "auto"
    return np.abs(mean) > 3.0 * np.sqrt(np.diag(cov))


def fit_posterior(
    estimator: Any,
    X: Any,
    y: Any,
    *,
    inference: Literal["nuts", "svi"] = "nuts",
    num_samples: int = 500,
    warmup_steps: int = 500,
    num_chains: int = 2,
    seed: int = 0,
    basis: Literal["active", "all"] = "active",
    hyperpriors: Hyperpriors | None = None,
    svi_steps: int = 2000,
    **kwargs: Any,
) -> RVMPosterior | OneVsRestPosterior:
    """Full posterior of a fitted ``RVR`` / ``RVC`` over its basis (NUTS or SVI).

    Uses only the estimator's public API: ``design_matrix(X, basis=...)``, ``alpha_``, ``beta_``,
    ``mean_``, ``relevance_indices_`` and, for classifiers, ``classes_``. The type-II ML estimates
    are the chains' start values.

    Parameters
    ----------
    estimator : fitted RVR or RVC
        A multi-class RVC (one-vs-rest, ``estimators_``) gives a :class:`OneVsRestPosterior`.
    X : array-like or torch.Tensor, shape (n, d)
        Training inputs (those the estimator was fitted on, for ``basis="all"``).
    y : array-like, shape (n,)
        Targets (regression) or labels among ``estimator.classes_`` (classification).
    inference : {"nuts", "svi"}
    num_samples, warmup_steps, num_chains, seed : see :func:`sample_posterior`.
    basis : {"active", "all"}
        ``"active"``: the basis kept by type-II ML (default). ``"all"``: every training row + bias.
    hyperpriors : Hyperpriors, optional
        Default ``Hyperpriors()`` (rates relative to ``var(y)``).
    svi_steps : int
        Optimisation steps for ``inference="svi"``.
    **kwargs
        Further :func:`sample_posterior` settings (``target_accept_prob``, ``svi_lr``, ...), and
        for classifiers ``parametrisation`` (default: centred where the type-II fit's weight is
        more than 3 standard deviations from 0, see :class:`SparseBayesClassificationModel`).

    Returns
    -------
    RVMPosterior
        ``predict(X, return_std=True)`` (regression), ``predict_proba(X)`` (classification),
        ``diagnostics``, ``to_arviz()``.
    """
    y_arr = _checked_targets(estimator, X, y, basis, kwargs)
    classes = getattr(estimator, "classes_", None)
    if classes is not None:
        classes = np.asarray(classes)
        unknown = ~np.isin(y_arr, classes)
        if unknown.any():
            raise ValueError(f"y has labels not in estimator.classes_: {np.unique(y_arr[unknown])}")
        if classes.size > 2:
            settings = {
                "inference": inference,
                "num_samples": num_samples,
                "warmup_steps": warmup_steps,
                "num_chains": num_chains,
                "basis": basis,
                "hyperpriors": hyperpriors,
                "svi_steps": svi_steps,
            }
            return _one_vs_rest_posterior(estimator, X, y_arr, classes, seed, settings, kwargs)
        Phi = estimator.design_matrix(X, basis=basis)
        param = kwargs.pop("parametrisation", None)
        if param is None:
            param = _well_determined_from_estimator(estimator, basis, int(Phi.shape[1]))
        model: Model = SparseBayesClassificationModel(
            Phi, (y_arr == classes[1]).astype(np.float64), hyperpriors, param
        )
    else:
        Phi = estimator.design_matrix(X, basis=basis)
        model = SparseBayesRegressionModel(Phi, y_arr.astype(np.float64), hyperpriors)
    init, names = _estimator_init(estimator, model, basis)
    frozen = copy.deepcopy(estimator)
    return sample_posterior(
        model,
        inference=inference,
        num_samples=num_samples,
        warmup_steps=warmup_steps,
        num_chains=num_chains,
        seed=seed,
        init=init,
        svi_steps=svi_steps,
        basis=basis,
        basis_names=names,
        design=functools.partial(frozen.design_matrix, basis=basis),
        classes=classes,
        **kwargs,
    )


def _one_vs_rest_posterior(
    estimator: Any,
    X: Any,
    y: np.ndarray,
    classes: np.ndarray,
    seed: int,
    settings: dict[str, Any],
    kwargs: dict[str, Any],
) -> OneVsRestPosterior:
    """:func:`fit_posterior` of each binary one-vs-rest classifier of a multi-class RVC (class
    ``k`` seeded from ``(seed, k)``)."""
    subs = getattr(estimator, "estimators_", None)
    if subs is None or len(subs) != classes.size:
        raise ValueError(
            f"{classes.size} classes but estimator.estimators_ does not hold one binary "
            "one-vs-rest classifier per class"
        )
    parts = []
    for k, (label, sub) in enumerate(zip(classes, subs, strict=True)):
        part = fit_posterior(
            sub,
            X,
            (y == label).astype(int),
            seed=int(np.random.SeedSequence([seed, k]).generate_state(1)[0] >> 1),
            **settings,
            **kwargs,
        )
        parts.append(part)
    return OneVsRestPosterior(classes=classes, posteriors=tuple(parts))


def _checked_targets(
    estimator: Any, X: Any, y: Any, basis: str, kwargs: Mapping[str, Any]
) -> np.ndarray:
    """``y`` as a 1-D numpy array, once :func:`fit_posterior`'s arguments are checked."""
    if basis not in ("active", "all"):
        raise ValueError(f"basis must be 'active' or 'all', got {basis!r}")
    for attr in ("alpha_", "design_matrix"):
        if not hasattr(estimator, attr):
            raise ValueError(f"estimator has no {attr!r}: fit it (RVR/RVC) before fit_posterior")
    for forbidden in ("basis", "basis_names", "design", "classes", "init"):
        if forbidden in kwargs:
            raise ValueError(f"{forbidden!r} is set by fit_posterior")
    n = int(X.shape[0]) if hasattr(X, "shape") else len(X)
    y_arr = y.detach().cpu().numpy() if isinstance(y, torch.Tensor) else np.asarray(y)
    if y_arr.ndim != 1 or y_arr.shape[0] != n:
        raise ValueError(f"y must be 1-D with {n} entries (one per row of X), got {y_arr.shape}")
    return y_arr
