"""Convergence diagnostics of posterior draws: R-hat and ESS from ArviZ, and their summary record.

R-hat is ArviZ's rank-normalised split R-hat (``az.rhat(method="rank")``: the larger of the bulk
and folded values) and ESS its bulk and tail effective sample sizes (``az.ess``), after Vehtari et
al. (2021). Nothing here is computed by hand; all ArviZ calls of this module sit in
:func:`_arviz_diagnostic` so a port to ArviZ 1.x stays local.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

__all__ = ["PosteriorDiagnostics", "effective_sample_size", "r_hat"]


def _arviz_diagnostic(draws: Any, what: Literal["rhat", "bulk", "tail"]) -> np.ndarray:
    """One ArviZ diagnostic of a ``(chains, draws, ...)`` array, per parameter."""
    import arviz as az

    x = np.asarray(draws, dtype=np.float64)
    dataset = az.convert_to_dataset({"x": x})
    if what == "rhat":
        out = az.rhat(dataset, method="rank")
    else:
        out = az.ess(dataset, method=what)
    return np.asarray(out["x"].values, dtype=np.float64).reshape(x.shape[2:])


def r_hat(draws: Any) -> np.ndarray:
    """Rank-normalised split R-hat (max of bulk and folded), per parameter, from ArviZ.

    Parameters
    ----------
    draws : array-like, shape (chains, draws, ...)
        At least 2 chains and 4 draws.

    Returns
    -------
    numpy.ndarray
        Shape ``draws.shape[2:]``; values below 1.01 indicate converged chains.
    """
    x = np.asarray(draws, dtype=float)
    if x.ndim < 2 or x.shape[0] < 2 or x.shape[1] < 4:
        raise ValueError(f"r_hat needs >= 2 chains and >= 4 draws, got shape {x.shape}")
    return _arviz_diagnostic(x, "rhat")


def effective_sample_size(draws: Any, kind: Literal["bulk", "tail"] = "bulk") -> np.ndarray:
    """Bulk (rank-normalised) or tail (5%/95% quantile) effective sample size, from ArviZ.

    Parameters
    ----------
    draws : array-like, shape (chains, draws, ...)
        At least 4 draws per chain.
    kind : {"bulk", "tail"}

    Returns
    -------
    numpy.ndarray
        Shape ``draws.shape[2:]``.
    """
    x = np.asarray(draws, dtype=float)
    if x.ndim < 2 or x.shape[1] < 4:
        raise ValueError(f"effective_sample_size needs >= 4 draws, got shape {x.shape}")
    if kind not in ("bulk", "tail"):
        raise ValueError(f"kind must be 'bulk' or 'tail', got {kind!r}")
    return _arviz_diagnostic(x, kind)


@dataclass(frozen=True)
class PosteriorDiagnostics:
    """Convergence diagnostics of a posterior fit; immutable.

    Attributes
    ----------
    inference : str
        ``"nuts"`` or ``"svi"``.
    r_hat, ess_bulk, ess_tail : dict of str to numpy.ndarray
        Per variable (``log_alpha``, ``log_beta``, ``weights``); empty for SVI (independent draws).
    divergences : tuple of int
        Number of divergent transitions after warm-up, per chain (empty for SVI).
    divergent_draws : tuple of tuple of int
        Indices (within the chain's kept draws) of the divergent transitions, per chain.
    acceptance_rate : tuple of float
        Mean Metropolis acceptance per chain (NUTS).
    step_size : tuple of float
        Adapted step size per chain (NUTS).
    elbo : numpy.ndarray or None
        ELBO per SVI step.
    wall_time_s : float
        Time spent in inference.
    """

    inference: str
    r_hat: dict[str, np.ndarray] = field(default_factory=dict)
    ess_bulk: dict[str, np.ndarray] = field(default_factory=dict)
    ess_tail: dict[str, np.ndarray] = field(default_factory=dict)
    divergences: tuple[int, ...] = ()
    divergent_draws: tuple[tuple[int, ...], ...] = field(default=(), repr=False)
    acceptance_rate: tuple[float, ...] = ()
    step_size: tuple[float, ...] = ()
    elbo: np.ndarray | None = field(default=None, repr=False)
    wall_time_s: float = 0.0

    @classmethod
    def from_nuts(
        cls, variables: dict[str, np.ndarray], stats: dict[str, list[Any]], wall_time_s: float
    ) -> PosteriorDiagnostics:
        """R-hat (when there are 2+ chains), bulk and tail ESS of ``(chains, draws, ...)`` draws."""
        several = next(iter(variables.values())).shape[0] > 1
        return cls(
            inference="nuts",
            r_hat={k: r_hat(v) for k, v in variables.items()} if several else {},
            ess_bulk={k: effective_sample_size(v, "bulk") for k, v in variables.items()},
            ess_tail={k: effective_sample_size(v, "tail") for k, v in variables.items()},
            divergences=tuple(len(d) for d in stats["divergent_draws"]),
            divergent_draws=tuple(stats["divergent_draws"]),
            acceptance_rate=tuple(stats["acceptance_rate"]),
            step_size=tuple(stats["step_size"]),
            wall_time_s=wall_time_s,
        )

    @property
    def max_r_hat(self) -> float:
        """Largest R-hat over all parameters (nan if not computed)."""
        vals = [np.nanmax(v) for v in self.r_hat.values() if np.size(v)]
        return float(max(vals)) if vals else float("nan")

    @property
    def min_ess_bulk(self) -> float:
        """Smallest bulk ESS over all parameters (nan if not computed)."""
        vals = [np.nanmin(v) for v in self.ess_bulk.values() if np.size(v)]
        return float(min(vals)) if vals else float("nan")

    @property
    def n_divergences(self) -> int:
        """Total number of divergent transitions."""
        return int(sum(self.divergences))

    def __str__(self) -> str:
        if self.inference == "svi":
            final = float(self.elbo[-1]) if self.elbo is not None and self.elbo.size else math.nan
            return f"SVI: final ELBO {final:.4g}, {self.wall_time_s:.1f} s"
        return (
            f"NUTS: max R-hat {self.max_r_hat:.4f}, min bulk ESS {self.min_ess_bulk:.0f}, "
            f"divergences {list(self.divergences)}, {self.wall_time_s:.1f} s"
        )
