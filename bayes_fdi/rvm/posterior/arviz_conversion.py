"""Posterior results as ArviZ ``InferenceData``, with every group ``az.loo`` / ``az.plot_ppc`` read.

Groups: ``posterior``, ``sample_stats`` (``diverging``, NUTS), ``observed_data``,
``log_likelihood`` (pointwise, one value per draw and training point) and
``posterior_predictive``. All ArviZ calls of this module sit in :func:`_to_inference_data`
(arviz 0.2x ``az.from_dict``), so a port to ArviZ 1.x stays local.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from bayes_fdi.rvm.posterior.results import OneVsRestPosterior, RVMPosterior

__all__ = ["one_vs_rest_to_arviz", "rvm_posterior_to_arviz"]

OBSERVED = "y"
OBSERVATION_DIM = "observation"


def _groups(
    post: RVMPosterior, suffix: str, basis_dim: str, seed: int
) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, list[str]], dict[str, Sequence[Any]]]:
    """The groups of one posterior, variables named ``<name><suffix>``."""
    groups: dict[str, dict[str, np.ndarray]] = {
        "posterior": {f"log_alpha{suffix}": post.log_alpha, f"weights{suffix}": post.weights},
        "sample_stats": {},
        "observed_data": {},
        "log_likelihood": {},
        "posterior_predictive": {},
    }
    dims = {f"log_alpha{suffix}": [basis_dim], f"weights{suffix}": [basis_dim]}
    coords: dict[str, Sequence[Any]] = {basis_dim: list(post.basis_names)}
    if post.log_beta is not None:
        groups["posterior"][f"log_beta{suffix}"] = post.log_beta
    if post.inference == "nuts":
        groups["sample_stats"]["diverging"] = post._diverging
    if post.observed is not None:
        name = f"{OBSERVED}{suffix}"
        observed = post.observed if post.kind == "regression" else post.observed.astype(np.int64)
        groups["observed_data"][name] = observed
        groups["log_likelihood"][name] = post.pointwise_log_likelihood()
        groups["posterior_predictive"][name] = post.posterior_predictive(seed)
        dims[name] = [OBSERVATION_DIM]
        coords[OBSERVATION_DIM] = np.arange(observed.size)
    return groups, dims, coords


def rvm_posterior_to_arviz(post: RVMPosterior, *, seed: int = 0) -> Any:
    """``InferenceData`` of one :class:`RVMPosterior` (see ``RVMPosterior.to_arviz``)."""
    groups, dims, coords = _groups(post, "", "basis", seed)
    attrs = {"inference": post.inference, "kind": post.kind, "basis": post.basis}
    return _to_inference_data(groups, coords=coords, dims=dims, attrs=attrs)


def one_vs_rest_to_arviz(post: OneVsRestPosterior, *, seed: int = 0) -> Any:
    """``InferenceData`` of a :class:`OneVsRestPosterior`, variables suffixed ``[class]``."""
    groups: dict[str, dict[str, np.ndarray]] = {}
    dims: dict[str, list[str]] = {}
    coords: dict[str, Sequence[Any]] = {}
    diverging = []
    for k, (label, part) in enumerate(zip(post.classes, post.posteriors, strict=True)):
        part_seed = int(np.random.SeedSequence([seed, k]).generate_state(1)[0])
        g, d, c = _groups(part, f"[{label}]", f"basis[{label}]", part_seed)
        if "diverging" in g["sample_stats"]:
            diverging.append(g["sample_stats"].pop("diverging"))
        for group, variables in g.items():
            groups.setdefault(group, {}).update(variables)
        dims.update(d)
        coords.update(c)
    if diverging:
        groups["sample_stats"]["diverging"] = np.any(diverging, axis=0)
    attrs = {"inference": post.inference, "kind": post.kind, "one_vs_rest": 1}
    return _to_inference_data(groups, coords=coords, dims=dims, attrs=attrs)


def _to_inference_data(
    groups: dict[str, dict[str, np.ndarray]],
    *,
    coords: dict[str, Sequence[Any]],
    dims: dict[str, list[str]],
    attrs: dict[str, Any],
) -> Any:
    """All ArviZ calls live here (arviz 0.2x ``from_dict``; add arviz 1.x here)."""
    import arviz as az

    return az.from_dict(
        **{group: variables or None for group, variables in groups.items()},
        coords=coords,
        dims=dims,
        attrs=attrs,
    )
