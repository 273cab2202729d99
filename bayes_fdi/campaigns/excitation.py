"""The ``[excitation]`` table of a campaign: which excitation family drives the runs.

A campaign with ``source = "excitation"`` draws the inputs (CV, P1, P2, T1) of its runs from one
of the generators of `bayes_fdi.actuator.excitation` (the families a training campaign uses)
or `bayes_fdi.actuator.excitation_signals` (further families). The table names the family and
sets its parameters; what is not set keeps the generator's default:

```toml
[campaign]
source = "excitation"

[excitation]
family = "sine-sum"            # see EXCITATION_FAMILIES (the key names the generator)
n_sines = 4                    # the generator's keyword parameters, as TOML values:
frequencies = [0.002, 0.1]     # a pair [low, high] where the default is a pair, a number or
cv_amplitude = [0.05, 0.25]    # an integer where it is one

[excitation.operating]         # optional: the operating range of P1, P2, T1
p1 = [2.6e6, 3.6e6]            # (bayes_fdi.actuator.excitation.OperatingRange; Pa, °C)
```

For ``family = "level-loop"`` the keys are the fields of
`~bayes_fdi.actuator.excitation.LevelLoop` (the loop), set directly in ``[excitation]``.
:func:`parse_excitation` checks every key and its type, then draws two seconds of one run so
that the generator's own range checks run at load time; every error names the key.
:func:`excitation_inputs` draws the inputs of a campaign's runs.

Written by hand: the mapping from a TOML table to the generators is this project's own.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType
from typing import Any, NamedTuple

from bayes_fdi.actuator import excitation as base
from bayes_fdi.actuator import excitation_signals as signals
from bayes_fdi.campaigns.spec import CampaignError

__all__ = [
    "EXCITATION_FAMILIES",
    "ExcitationFamily",
    "excitation_inputs",
    "family_parameters",
    "parse_excitation",
]


class ExcitationFamily(NamedTuple):
    """A generator of inputs that a campaign may name in ``[excitation] family``.

    ``generator(n_runs, duration, *, seed, **parameters)`` returns the inputs dataset. Where
    ``options`` is given (a NamedTuple class and the generator's keyword that takes it), the
    table's keys are that class's fields and are passed as one ``options`` object.
    """

    generator: Callable[..., Any]
    options: tuple[str, type] | None = None


#: The families a campaign can name, by the name the generator stores as ``generator``.
EXCITATION_FAMILIES: Mapping[str, ExcitationFamily] = MappingProxyType(
    {
        "sine-sum": ExcitationFamily(base.sine_sum_inputs),
        "step-ramp": ExcitationFamily(base.step_ramp_inputs),
        "level-loop": ExcitationFamily(base.level_loop_inputs, ("loop", base.LevelLoop)),
        "telegraph": ExcitationFamily(signals.telegraph_inputs),
        "chirp": ExcitationFamily(signals.chirp_inputs),
        "flow-loop": ExcitationFamily(signals.flow_loop_inputs),
    }
)
_NOT_PARAMETERS = {"n_runs", "duration", "seed", "operating"}


def family_parameters(family: str) -> dict[str, Any]:
    """The parameters a family's table may set, with their defaults (which give their kind:
    a pair, a number or an integer)."""
    spec = EXCITATION_FAMILIES[family]
    if spec.options is not None:
        return dict(spec.options[1]()._asdict())
    signature = inspect.signature(spec.generator)
    return {
        name: p.default
        for name, p in signature.parameters.items()
        if p.kind is inspect.Parameter.KEYWORD_ONLY and name not in _NOT_PARAMETERS
    }


def _accepts_operating(family: str) -> bool:
    return "operating" in inspect.signature(EXCITATION_FAMILIES[family].generator).parameters


def _value(value: Any, default: Any, key: str) -> Any:
    """``value`` checked against the kind of ``default``: an int, a float or a pair."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise CampaignError(f"{key} must be true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise CampaignError(f"{key} must be an integer, got {value!r}")
        return int(value)
    if isinstance(default, float):
        return _finite(value, key)
    if isinstance(default, tuple):
        if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2:
            raise CampaignError(f"{key} must be a pair [low, high], got {value!r}")
        low, high = (_finite(v, key) for v in value)
        if low > high:
            raise CampaignError(f"{key} must have low <= high, got {[low, high]}")
        return (low, high)
    raise CampaignError(f"{key}: cannot be set from a campaign file")  # pragma: no cover


def _finite(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise CampaignError(f"{key} must be a number, got {value!r}")
    if not math.isfinite(float(value)):
        raise CampaignError(f"{key} must be finite, got {value!r}")
    return float(value)


def _checked(table: Mapping[str, Any], defaults: Mapping[str, Any], prefix: str) -> dict:
    extra = sorted(set(table) - set(defaults))
    if extra:
        raise CampaignError(
            f"{prefix}.{extra[0]}: unknown key (allowed: {', '.join(sorted(defaults))})"
        )
    return {k: _value(v, defaults[k], f"{prefix}.{k}") for k, v in table.items()}


def parse_excitation(value: Any, key: str = "excitation") -> dict[str, Any]:
    """Validate an ``[excitation]`` table; ``key`` names it in errors.

    Returns
    -------
    dict
        ``family``, ``parameters`` (the keys set, as the generator takes them: pairs as tuples)
        and ``operating`` (the ``[excitation.operating]`` keys set).

    Raises
    ------
    CampaignError
        Naming the offending key, e.g. ``excitation.n_sine: unknown key (allowed: ...)``.
    """
    if not isinstance(value, Mapping):
        raise CampaignError(f"{key} must be a table, got {value!r}")
    table = dict(value)
    if "family" not in table:
        raise CampaignError(f"{key}.family is missing (one of {', '.join(EXCITATION_FAMILIES)})")
    family = table.pop("family")
    if family not in EXCITATION_FAMILIES:
        raise CampaignError(
            f"{key}.family must be one of {', '.join(EXCITATION_FAMILIES)}, got {family!r}"
        )
    operating_table = table.pop("operating", {})
    if not isinstance(operating_table, Mapping):
        raise CampaignError(f"{key}.operating must be a table, got {operating_table!r}")
    if operating_table and not _accepts_operating(family):
        raise CampaignError(f"{key}.operating: the {family} family sets its own operating point")
    parameters = _checked(table, family_parameters(family), key)
    operating = _checked(operating_table, base.OperatingRange()._asdict(), f"{key}.operating")
    out = {"family": family, "parameters": parameters, "operating": operating}
    try:  # the generator's own range checks, on two seconds of one run
        excitation_inputs(out, 1, 2, seed=0)
    except ValueError as exc:
        raise CampaignError(f"{key}: {exc}") from None
    return out


def excitation_inputs(excitation: Mapping[str, Any], n_runs: int, duration: int, *, seed: int):
    """The inputs of ``n_runs`` runs of ``duration`` s drawn by a parsed excitation table
    (:func:`parse_excitation`); run ``r`` depends on ``seed`` and ``r`` only."""
    family = excitation["family"]
    spec = EXCITATION_FAMILIES[family]
    kwargs: dict[str, Any] = dict(excitation["parameters"])
    if spec.options is not None:
        name, options = spec.options
        kwargs = {name: options(**kwargs)}
    if excitation["operating"]:
        kwargs["operating"] = base.OperatingRange(**excitation["operating"])
    return spec.generator(n_runs, duration, seed=int(seed), **kwargs)
