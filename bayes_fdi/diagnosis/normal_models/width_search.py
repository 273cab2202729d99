"""Kernel-width searches of the normal models: by summed evidence over a grid, or by a GA.

`evidence_grid_search` (the default of `NormalModels` and of ``reproduce``) fits the regressor
at every width of a grid on a seeded subsample and takes the width of largest log evidence
summed over the outputs; `genetic_width_search` is the paper's GA on a held-out MSE.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "EVIDENCE_TIE_NATS",
    "WIDTH_GRID",
    "EvidenceGridResult",
    "GAResult",
    "evidence_grid_search",
    "genetic_width_search",
]

#: Default candidate RBF widths of `NormalModels`' ``"evidence-grid"`` width search (the same
#: grid as `bayes_fdi.paper.reproduce.REGRESSION_WIDTHS`; the inputs are normalised to [0,
#: 1]).
WIDTH_GRID: tuple[float, ...] = (0.05, 0.1, 0.2, 0.4, 0.8)
#: Summed log evidences within this many nats of the largest are a tie, won by the first such
#: width in grid order. A difference of 1e-6 nats is a Bayes factor of 1.000001 (no preference),
#: and far above the rounding of a log evidence of order 1e3 to 1e4 (about 1e-12 relative) on
#: any BLAS code path, so near-ties are resolved the same way on every machine.
EVIDENCE_TIE_NATS: float = 1e-6


class GAResult(NamedTuple):
    """Result of `genetic_width_search`.

    Attributes
    ----------
    width : float
        The best kernel width found.
    mse : float
        Its validation mean squared error.
    history : numpy.ndarray
        ``(generations + 1, 2)``: best width and best MSE after each generation (row 0: the
        initial population).
    n_evaluations : int
        Number of distinct model fits.
    """

    width: float
    mse: float
    history: np.ndarray
    n_evaluations: int


def genetic_width_search(
    make_estimator: Callable[[float], Any],
    X_train: np.ndarray,
    y_train: np.ndarray,
    X_val: np.ndarray,
    y_val: np.ndarray,
    *,
    bounds: tuple[float, float] = (1e-3, 10.0),
    population: int = 12,
    generations: int = 10,
    random_state: int | None = 0,
) -> GAResult:
    """Minimise validation MSE over a kernel width with a small real-coded genetic algorithm.

    The genome is ``log10(width)`` within ``bounds``. Each generation keeps the best individual
    (elitism), fills the rest by binary-tournament selection, blend crossover (BLX-0.5) and
    Gaussian mutation (probability 0.3, standard deviation 10 % of the log-range), clipped to
    the bounds. Fitness is the mean squared error of ``make_estimator(width)`` fitted on
    ``(X_train, y_train)`` and evaluated on ``(X_val, y_val)``; a fit that raises is given
    infinite MSE. The paper tuned its RVR kernel width the same way (its section 3.2).

    Parameters
    ----------
    make_estimator
        ``width -> unfitted regressor``.
    X_train, y_train, X_val, y_val
        Training and validation data.
    bounds
        ``(low, high)`` search range of the width (both > 0).
    population, generations
        GA sizes; the cost is at most ``population * (generations + 1)`` fits.
    random_state
        Seed of the GA's own generator.

    Returns
    -------
    GAResult
    """
    low, high = (float(b) for b in bounds)
    if not (0 < low < high) or not (math.isfinite(low) and math.isfinite(high)):
        raise ValueError(f"bounds must satisfy 0 < low < high, got {bounds}")
    if population < 2 or generations < 0:
        raise ValueError("population must be >= 2 and generations >= 0")
    rng = np.random.default_rng(random_state)
    lo, hi = math.log10(low), math.log10(high)
    cache: dict[float, float] = {}

    def fitness(g: float) -> float:
        key = round(float(g), 10)
        if key not in cache:
            try:
                est = make_estimator(10.0**key)
                est.fit(X_train, y_train)
                pred = np.asarray(est.predict(X_val), dtype=np.float64).ravel()
                mse = float(np.mean((pred - y_val) ** 2))
                cache[key] = mse if math.isfinite(mse) else math.inf
            except (ValueError, np.linalg.LinAlgError, RuntimeError):
                cache[key] = math.inf
        return cache[key]

    genomes = (
        np.linspace(lo, hi, population)
        + rng.uniform(-0.5, 0.5, population) * (hi - lo) / population
    )
    genomes = np.clip(genomes, lo, hi)
    scores = np.array([fitness(g) for g in genomes])
    history = [(10.0 ** genomes[np.argmin(scores)], scores.min())]
    sigma_mut = 0.1 * (hi - lo)
    for _ in range(generations):
        best = int(np.argmin(scores))
        children = [genomes[best]]
        while len(children) < population:
            parents = []
            for _k in range(2):
                i, j = rng.integers(0, population, 2)
                parents.append(genomes[i] if scores[i] <= scores[j] else genomes[j])
            a, b = min(parents), max(parents)
            span = b - a
            child = rng.uniform(a - 0.5 * span, b + 0.5 * span)
            if rng.random() < 0.3:
                child += rng.normal(0.0, sigma_mut)
            children.append(float(np.clip(child, lo, hi)))
        genomes = np.array(children)
        scores = np.array([fitness(g) for g in genomes])
        history.append((10.0 ** genomes[np.argmin(scores)], scores.min()))
    best = int(np.argmin(scores))
    if not math.isfinite(scores[best]):
        raise ValueError("every kernel width tried by the genetic search failed to fit")
    return GAResult(
        width=float(10.0 ** genomes[best]),
        mse=float(scores[best]),
        history=np.array(history, dtype=np.float64),
        n_evaluations=len(cache),
    )


class EvidenceGridResult(NamedTuple):
    """Result of `evidence_grid_search`.

    Attributes
    ----------
    width : float
        The grid width of largest summed log evidence (the first in grid order of those within
        `EVIDENCE_TIE_NATS` of the largest).
    log_evidence : dict
        Width -> log evidence summed over the outputs.
    log_evidence_by_output : dict
        Output name -> (width -> log evidence of that output's model).
    n_samples : int
        Samples each model was fitted on.
    """

    width: float
    log_evidence: dict[float, float]
    log_evidence_by_output: dict[str, dict[float, float]]
    n_samples: int


def evidence_grid_search(
    make_estimator: Callable[[float], Any],
    U: np.ndarray,
    targets: dict[str, np.ndarray],
    widths: Sequence[float],
    *,
    max_samples: int | None = None,
    rng: np.random.Generator | None = None,
) -> EvidenceGridResult:
    """One kernel width for several outputs by maximum summed log evidence over a grid.

    Each output's model ``make_estimator(width)`` is fitted at every grid width on the same
    samples (a seeded random subset of ``max_samples`` of them when there are more: row
    indices ``np.sort(rng.choice(n, max_samples, replace=False))``); the width whose log
    marginal likelihoods (the fitted models' ``log_evidence_``), summed over the outputs, is
    largest wins (widths within `EVIDENCE_TIE_NATS` of it tie; the first in grid order wins).
    This is the width search of `NormalModels` (``width_search="evidence-grid"``)
    and of `bayes_fdi.paper.reproduce.select_regression_width`.

    Parameters
    ----------
    make_estimator
        ``width -> unfitted regressor`` whose fitted form has a ``log_evidence_`` attribute
        (e.g. ``lambda w: bayes_fdi.rvm.RVR(kernel="rbf", width=w)``).
    U
        ``(n, d)`` inputs (finite).
    targets
        Output name -> ``(n,)`` targets (finite).
    widths
        Candidate widths (non-empty).
    max_samples
        Subsample size; ``None`` fits on all ``n`` samples.
    rng
        Generator of the subsample (needed only when it is drawn).

    Returns
    -------
    EvidenceGridResult
    """
    widths = [float(w) for w in widths]
    if not widths:
        raise ValueError("the width grid is empty")
    if not targets:
        raise ValueError("no targets to choose a width for")
    n = U.shape[0]
    rows = np.arange(n)
    if max_samples is not None and n > max_samples:
        if rng is None:
            raise ValueError("a subsample needs a random generator (rng)")
        rows = np.sort(rng.choice(n, size=max_samples, replace=False))
    by_output: dict[str, dict[float, float]] = {}
    for name, y in targets.items():
        by_output[name] = {}
        for w in widths:
            est = make_estimator(w).fit(U[rows], np.asarray(y)[rows])
            if not hasattr(est, "log_evidence_"):
                raise ValueError(
                    f"{type(est).__name__} has no log_evidence_ after fit: the evidence grid "
                    "search needs a Bayesian regressor such as bayes_fdi.rvm.RVR"
                )
            by_output[name][w] = float(est.log_evidence_)
    total = {w: float(sum(by_output[name][w] for name in targets)) for w in widths}
    best = max(total.values())
    return EvidenceGridResult(
        width=next(w for w in widths if total[w] >= best - EVIDENCE_TIE_NATS),
        log_evidence=total,
        log_evidence_by_output=by_output,
        n_samples=int(rows.size),
    )
