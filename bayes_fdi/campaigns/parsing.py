"""Campaign files: the TOML schema and its validation into a :class:`Campaign`.

:func:`load_campaign` reads a campaign file and :func:`parse_campaign` validates the parsed
table, one function per table of the file (``[campaign]``, ``[inputs]``, ``[faults]``,
``[[scenarios]]``; ``[excitation]`` in `bayes_fdi.campaigns.excitation`), into the immutable
`~bayes_fdi.campaigns.spec.Campaign`.

The schema (also in ``docs/data.md``):

```toml
[campaign]
name = "paper-simulated"       # required; stored as the dataset's ``campaign`` attribute
description = "..."            # optional free text
seed = 2026                    # required int >= 0; ``simulate_campaign(seed=)`` overrides it
duration = 350                 # required int > 0: seconds per run (1 Hz samples)
source = "benchmark-inputs"    # "benchmark-inputs" (DGen sines) | "lublin-example" (real hour)
                               # | "excitation" (an excitation family: [excitation] below)
runs_per_state = 190           # int > 0 (state mode; omit when [[scenarios]] are given)
states = "all"                 # "all" (fn, f1..f19) or a list such as ["fn", "f1", "f17"]
batch_size = 64                # runs simulated together (memory/speed only; the result does
                               # not depend on it)

[inputs]                       # how the inputs vary from run to run
vary = true                    # benchmark-inputs: per-run sine phases U[0, 2 pi) and
                               # amplitude factors U[0.8, 1.2] (actuator.benchmark_inputs)
window = "random"              # lublin-example: "random" | "even" offsets of 350 s windows

[excitation]                   # source = "excitation" only: the family and its parameters
family = "step-ramp"           # (bayes_fdi.campaigns.excitation; docs/data.md lists them)
hold_seconds = [20.0, 300.0]

[faults]                       # defaults for every fault (state mode)
strength = [0.5, 1.0]          # magnitude range, drawn per run; 0 < low <= high <= 1
draw = "uniform"               # "uniform" (independent draws) | "stratified" (one draw in each
                               # of runs_per_state equal slices of the range, in random order)
onset = 0.0                    # s; 0 = the whole run is faulty (the paper's per-run features)
profile = "abrupt"             # "abrupt" | "incipient"
ramp = 0.0                     # s; > 0 for incipient, 0 for abrupt

[faults.f4]                    # per-fault overrides of any of the keys above, plus
strength = [0.05, 0.2]
direction = 1                  # sign of the strength: +1, or -1 for the signed faults
                               # (f4, f12, f13, f14, f17, f19); default the benchmark's
                               # direction (-1 for f12, f14, f19; +1 otherwise)

[[scenarios]]                  # scenario mode: explicit runs instead of runs_per_state/states
state = "f1"                   # "fn" or "f1".."f19"
strength = 0.25                # magnitude in (0, 1] (sign from direction); omit for "fn"
direction = 1                  # optional, as above
onset = 900.0
profile = "abrupt"
ramp = 0.0
runs = 1                       # repetitions (different noise and input draws)
```

Every error names the offending key, e.g. ``campaign.duration must be > 0``,
``faults.f42: unknown fault``, ``faults.f2.strength: [0.5, 1.5] not within [0, 1]``.
"""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

from bayes_fdi.campaigns.spec import (
    FAULT_DIRECTION,
    FAULTS,
    LUBLIN_HOUR,
    PROFILES,
    SIGNED_FAULTS,
    SOURCES,
    STATES,
    STRENGTH_DRAWS,
    WINDOWS,
    Campaign,
    CampaignError,
    FaultSpec,
    Scenario,
)

__all__ = ["apply_overrides", "check_seed", "load_campaign", "parse_campaign", "thaw"]

_CAMPAIGN_KEYS = {
    "name",
    "description",
    "seed",
    "duration",
    "source",
    "runs_per_state",
    "states",
    "batch_size",
}
_FAULT_KEYS = {"strength", "draw", "onset", "profile", "ramp", "direction"}
_SCENARIO_KEYS = {"state", "strength", "onset", "profile", "ramp", "runs", "direction"}
_INPUT_KEYS = {
    "benchmark-inputs": {"vary"},
    "lublin-example": {"window"},
}


def _fail(key: str, message: str) -> CampaignError:
    if message.startswith(("must", "is ", "does ")):
        return CampaignError(f"{key} {message}")
    return CampaignError(f"{key}: {message}")


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(key, f"must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise _fail(key, f"must be finite, got {value!r}")
    return out


def _integer(value: Any, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail(key, f"must be an integer, got {value!r}")
    return int(value)


def check_seed(value: Any, key: str) -> int:
    """``value`` as a seed (an integer >= 0), or a `CampaignError` naming ``key``."""
    seed = _integer(value, key)
    if seed < 0:
        raise _fail(key, f"must be >= 0, got {seed}")
    return seed


def _table(value: Any, key: str) -> dict:
    if not isinstance(value, Mapping):
        raise _fail(key, f"must be a table, got {value!r}")
    return dict(value)


def _unknown(table: Mapping, allowed: set[str], prefix: str) -> None:
    extra = sorted(set(table) - allowed)
    if extra:
        key = f"{prefix}.{extra[0]}" if prefix else extra[0]
        raise _fail(key, f"unknown key (allowed: {', '.join(sorted(allowed))})")


def _strength_range(value: Any, key: str) -> tuple[float, float]:
    if isinstance(value, int | float) and not isinstance(value, bool):
        value = [value, value]
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2:
        raise _fail(key, f"must be a magnitude range [low, high], got {value!r}")
    low, high = (_number(v, key) for v in value)
    if not 0.0 < low <= high <= 1.0:
        raise _fail(
            key,
            f"{[low, high]} not within [0, 1] with 0 < low <= high (magnitudes; the sign comes "
            "from direction)",
        )
    return low, high


def _strength_draw(value: Any, key: str) -> str:
    if not isinstance(value, str) or value not in STRENGTH_DRAWS:
        raise _fail(key, f"must be one of {', '.join(STRENGTH_DRAWS)}, got {value!r}")
    return value


def _direction(value: Any, key: str, fault: str) -> int:
    d = _integer(value, key)
    if d not in (-1, 1):
        raise _fail(key, f"must be 1 or -1, got {d}")
    if d == -1 and fault not in SIGNED_FAULTS:
        raise _fail(
            key,
            f"{fault} only takes positive strengths (signed faults: "
            f"{', '.join(sorted(SIGNED_FAULTS, key=lambda f: int(f[1:])))})",
        )
    return d


def _timing(table: Mapping, key: str, duration: int) -> tuple[float, str, float]:
    onset = _number(table["onset"], f"{key}.onset")
    if not 0.0 <= onset < duration:
        raise _fail(f"{key}.onset", f"must lie in [0, campaign.duration={duration}), got {onset:g}")
    profile = table["profile"]
    if profile not in PROFILES:
        raise _fail(f"{key}.profile", f"must be 'abrupt' or 'incipient', got {profile!r}")
    ramp = _number(table["ramp"], f"{key}.ramp")
    if profile == "incipient" and ramp <= 0:
        raise _fail(f"{key}.ramp", f"must be > 0 s for an incipient profile, got {ramp:g}")
    if profile == "abrupt" and ramp != 0:
        raise _fail(f"{key}.ramp", f"must be 0 for an abrupt profile, got {ramp:g}")
    return onset, profile, ramp


def parse_campaign(table: Mapping[str, Any], *, path: str | None = None) -> Campaign:
    """Validate a campaign table (the parsed TOML) into a :class:`Campaign`.

    Raises
    ------
    CampaignError
        (a ``ValueError``) naming the offending key.
    """
    table = _table(table, "campaign file")
    _unknown(table, {"campaign", "inputs", "faults", "scenarios", "excitation"}, "")
    if "campaign" not in table:
        raise _fail("campaign", "is missing (a [campaign] table is required)")
    c = _table(table["campaign"], "campaign")
    header = _campaign_header(c)
    duration, source = header["duration"], header["source"]
    inputs = _inputs(table.get("inputs", {}), source)
    excitation = _excitation(table, source)
    faults = _faults(table.get("faults", {}), duration)
    scenarios = _scenarios(table.get("scenarios", []), duration)
    states, runs_per_state = _states(c, scenarios)
    return Campaign(
        name=header["name"],
        seed=header["seed"],
        duration=duration,
        source=source,
        states=states,
        runs_per_state=runs_per_state,
        batch_size=header["batch_size"],
        inputs=MappingProxyType(inputs),
        faults=MappingProxyType(faults),
        scenarios=tuple(scenarios),
        description=header["description"],
        excitation=_freeze(excitation),
        raw=_freeze(table),
        path=path,
    )


def _campaign_header(c: dict) -> dict[str, Any]:
    """The ``[campaign]`` table but for its states: name, description, seed, duration, source
    and batch size, validated."""
    _unknown(c, _CAMPAIGN_KEYS, "campaign")
    for key in ("name", "seed", "duration", "source"):
        if key not in c:
            raise _fail(f"campaign.{key}", "is missing")
    name = c["name"]
    if not isinstance(name, str) or not name.strip():
        raise _fail("campaign.name", f"must be a non-empty string, got {name!r}")
    description = c.get("description", "")
    if not isinstance(description, str):
        raise _fail("campaign.description", f"must be a string, got {description!r}")
    seed = check_seed(c["seed"], "campaign.seed")
    duration = _integer(c["duration"], "campaign.duration")
    if duration <= 0:
        raise _fail("campaign.duration", f"must be > 0, got {duration}")
    source = c["source"]
    if source not in SOURCES:
        raise _fail("campaign.source", f"must be one of {', '.join(SOURCES)}, got {source!r}")
    if source == "lublin-example" and duration > LUBLIN_HOUR:
        raise _fail(
            "campaign.duration",
            f"must be <= {LUBLIN_HOUR} s for source 'lublin-example' (the real hour), "
            f"got {duration}",
        )
    batch_size = _integer(c.get("batch_size", 64), "campaign.batch_size")
    if batch_size <= 0:
        raise _fail("campaign.batch_size", f"must be > 0, got {batch_size}")
    return {
        "name": name,
        "description": description,
        "seed": seed,
        "duration": duration,
        "source": source,
        "batch_size": batch_size,
    }


def _inputs(value: Any, source: str) -> dict:
    """The ``[inputs]`` table of ``source``, validated, with its defaults filled in."""
    inputs = _table(value, "inputs")
    if source == "excitation":
        if inputs:
            raise _fail(f"inputs.{sorted(inputs)[0]}", "is not used with source 'excitation' "
                        "(the [excitation] table sets the inputs)")  # fmt: skip
        return inputs
    _unknown(inputs, _INPUT_KEYS[source], "inputs")
    if source == "benchmark-inputs":
        vary = inputs.setdefault("vary", True)
        if not isinstance(vary, bool):
            raise _fail("inputs.vary", f"must be true or false, got {vary!r}")
    else:
        window = inputs.setdefault("window", "random")
        if window not in WINDOWS:
            raise _fail("inputs.window", f"must be 'random' or 'even', got {window!r}")
    return inputs


def _excitation(table: Mapping[str, Any], source: str) -> dict[str, Any]:
    """The ``[excitation]`` table: required with ``source = "excitation"``, refused otherwise."""
    if source != "excitation":
        if "excitation" in table:
            raise _fail("excitation", "is only for campaign.source = 'excitation'")
        return {}
    if "excitation" not in table:
        raise _fail("excitation", "is missing (source 'excitation' needs an [excitation] table)")
    from bayes_fdi.campaigns.excitation import parse_excitation

    return parse_excitation(table["excitation"])


def _faults(value: Any, duration: int) -> dict[str, FaultSpec]:
    """The ``[faults]`` table: every fault's defaults merged with its own ``[faults.fN]``."""
    faults_table = _table(value, "faults")
    defaults = {
        "strength": [0.5, 1.0], "draw": "uniform", "onset": 0.0, "profile": "abrupt", "ramp": 0.0
    }  # fmt: skip
    overrides: dict[str, dict] = {}
    for key, item in faults_table.items():
        if key in _FAULT_KEYS - {"direction"}:
            defaults[key] = item
        elif key == "direction":
            raise _fail("faults.direction", "is per fault only (set faults.fN.direction)")
        elif key in FAULTS:
            sub = _table(item, f"faults.{key}")
            _unknown(sub, _FAULT_KEYS, f"faults.{key}")
            overrides[key] = sub
        else:
            raise _fail(
                f"faults.{key}",
                "unknown fault (faults are f1..f19; keys: "
                f"{', '.join(sorted(_FAULT_KEYS - {'direction'}))})",
            )
    _strength_range(defaults["strength"], "faults.strength")
    _strength_draw(defaults["draw"], "faults.draw")
    _timing(defaults, "faults", duration)
    faults: dict[str, FaultSpec] = {}
    for f in FAULTS:
        merged = {**defaults, **overrides.get(f, {})}
        key = f"faults.{f}" if f in overrides else "faults"
        strength = _strength_range(
            merged["strength"],
            f"faults.{f}.strength" if "strength" in overrides.get(f, {}) else "faults.strength",
        )
        onset, profile, ramp = _timing(merged, key, duration)
        direction = _direction(
            merged.get("direction", FAULT_DIRECTION[f]), f"faults.{f}.direction", f
        )
        draw_key = f"faults.{f}.draw" if "draw" in overrides.get(f, {}) else "faults.draw"
        draw = _strength_draw(merged["draw"], draw_key)
        faults[f] = FaultSpec(strength, direction, onset, profile, ramp, draw)
    return faults


def _scenarios(value: Any, duration: int) -> list[Scenario]:
    """The ``[[scenarios]]`` array of tables (empty in state mode)."""
    if not isinstance(value, list):
        raise _fail("scenarios", "must be an array of tables ([[scenarios]])")
    return [_scenario(s, f"scenarios[{i}]", duration) for i, s in enumerate(value)]


def _scenario(value: Any, key: str, duration: int) -> Scenario:
    """One ``[[scenarios]]`` table; ``key`` names it in errors."""
    s = _table(value, key)
    _unknown(s, _SCENARIO_KEYS, key)
    if "state" not in s:
        raise _fail(f"{key}.state", "is missing")
    state = s["state"]
    if state not in STATES:
        raise _fail(f"{key}.state", f"unknown state {state!r} (states are fn, f1..f19)")
    runs = _integer(s.get("runs", 1), f"{key}.runs")
    if runs <= 0:
        raise _fail(f"{key}.runs", f"must be > 0, got {runs}")
    if state == "fn":
        extra = sorted(set(s) - {"state", "runs"})
        if extra:
            raise _fail(f"{key}.{extra[0]}", "does not apply to the fault-free state fn")
        return Scenario("fn", 0.0, 0.0, "abrupt", 0.0, runs)
    if "strength" not in s:
        raise _fail(f"{key}.strength", "is missing")
    magnitude = _number(s["strength"], f"{key}.strength")
    if not 0.0 < magnitude <= 1.0:
        raise _fail(
            f"{key}.strength",
            f"{magnitude:g} not within (0, 1] (a magnitude; the sign comes from direction)",
        )
    direction = _direction(s.get("direction", FAULT_DIRECTION[state]), f"{key}.direction", state)
    timing = {
        "onset": s.get("onset", 0.0),
        "profile": s.get("profile", "abrupt"),
        "ramp": s.get("ramp", 0.0),
    }
    onset, profile, ramp = _timing(timing, key, duration)
    return Scenario(state, direction * magnitude, onset, profile, ramp, runs)


def _states(c: dict, scenarios: list[Scenario]) -> tuple[tuple[str, ...], int]:
    """The states and runs per state: from ``[campaign]`` in state mode, from the scenarios
    (0 runs per state) in scenario mode."""
    if scenarios:
        for key in ("runs_per_state", "states"):
            if key in c:
                raise _fail(f"campaign.{key}", "must be omitted when [[scenarios]] are given")
        return tuple(dict.fromkeys(s.state for s in scenarios)), 0
    if "runs_per_state" not in c:
        raise _fail("campaign.runs_per_state", "is missing (or give [[scenarios]])")
    runs_per_state = _integer(c["runs_per_state"], "campaign.runs_per_state")
    if runs_per_state <= 0:
        raise _fail("campaign.runs_per_state", f"must be > 0, got {runs_per_state}")
    raw_states = c.get("states", "all")
    if raw_states == "all":
        return STATES, runs_per_state
    if isinstance(raw_states, list) and raw_states:
        for s in raw_states:
            if s not in STATES:
                raise _fail("campaign.states", f"unknown state {s!r} (states are fn, f1..f19)")
        if len(set(raw_states)) != len(raw_states):
            raise _fail("campaign.states", "lists a state twice")
        return tuple(raw_states), runs_per_state
    raise _fail("campaign.states", f'must be "all" or a list of states, got {raw_states!r}')


def load_campaign(path: str | os.PathLike, **overrides: Any) -> Campaign:
    """Read and validate a campaign TOML file.

    Parameters
    ----------
    path
        The ``.toml`` file.
    **overrides
        Values replacing those of the file before validation: bare names are ``[campaign]`` keys
        (``runs_per_state=2``), dotted names address any table (``**{"faults.onset": 10}``).

    Returns
    -------
    Campaign
    """
    path = os.fspath(path)
    try:
        with open(path, "rb") as handle:
            table = tomllib.load(handle)
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{path}: not valid TOML: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise CampaignError(f"{path}: not valid TOML: not UTF-8 text ({exc.reason})") from exc
    except IsADirectoryError:
        raise CampaignError(f"{path}: is a folder, not a campaign file") from None
    try:
        return parse_campaign(apply_overrides(table, overrides), path=path)
    except CampaignError as exc:
        raise CampaignError(f"{path}: {exc}") from None


def apply_overrides(table: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict:
    """A mutable copy of ``table`` with ``overrides`` set: bare keys in ``[campaign]``, dotted
    keys (``"faults.onset"``) in any table (created where missing)."""
    table = thaw(table)
    for key, value in overrides.items():
        parts = key.split(".") if "." in key else ["campaign", key]
        node = table
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise CampaignError(f"{key}: cannot override inside a non-table")
        node[parts[-1]] = value
    return table


def _freeze(value: Any) -> Any:
    if isinstance(value, Mapping):
        return MappingProxyType({k: _freeze(v) for k, v in value.items()})
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    return value


def thaw(value: Any) -> Any:
    """A mutable copy of a (frozen) TOML value: mappings as dicts, sequences as lists."""
    if isinstance(value, Mapping):
        return {k: thaw(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [thaw(v) for v in value]
    return value
