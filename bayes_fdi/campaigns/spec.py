"""Campaign records: the immutable :class:`Campaign` and the constants of its schema.

A campaign says which actuator states to simulate, how many runs of how many seconds, which
inputs drive the model and how strong the faults are. :class:`Campaign` holds a validated
campaign (:class:`FaultSpec` per fault, :class:`Scenario` per explicit scenario) and draws the
labels of its runs (:class:`RunSpec`); `bayes_fdi.campaigns.parsing` reads and validates a TOML
file into one, `bayes_fdi.campaigns.simulation` simulates it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "FAULTS",
    "FAULT_DIRECTION",
    "LUBLIN_HOUR",
    "PROFILES",
    "SIGNED_FAULTS",
    "SOURCES",
    "STATES",
    "STRENGTH_DRAWS",
    "WINDOWS",
    "Campaign",
    "CampaignError",
    "FaultSpec",
    "RunSpec",
    "Scenario",
]

STATES: tuple[str, ...] = ("fn", *(f"f{i}" for i in range(1, 20)))
FAULTS: tuple[str, ...] = STATES[1:]
SOURCES: tuple[str, ...] = ("benchmark-inputs", "lublin-example", "excitation")
PROFILES: tuple[str, ...] = ("abrupt", "incipient")
#: How a fault's strengths are drawn over its runs: independently and uniformly in its range, or
#: one in each of ``runs_per_state`` equal slices of the range (stratified), in a random order.
STRENGTH_DRAWS: tuple[str, ...] = ("uniform", "stratified")
WINDOWS: tuple[str, ...] = ("random", "even")
#: Faults whose strength may be negative in the benchmark (fault vector in [-1, 1]).
SIGNED_FAULTS: frozenset[str] = frozenset({"f4", "f12", "f13", "f14", "f17", "f19"})
#: The benchmark's direction of each fault (DGen mask): -1 for f12, f14, f19; +1 otherwise.
FAULT_DIRECTION: Mapping[str, int] = MappingProxyType(
    {f: -1 if f in {"f12", "f14", "f19"} else 1 for f in FAULTS}
)
#: Length of the packaged real hour (s).
LUBLIN_HOUR = 3600


class CampaignError(ValueError):
    """A campaign file or table is invalid; the message names the key."""


class FaultSpec(NamedTuple):
    """How the strength and timing of one fault are drawn in state mode."""

    strength: tuple[float, float]  #: magnitude range
    direction: int  #: +1 or -1
    onset: float  #: s
    profile: str  #: "abrupt" | "incipient"
    ramp: float  #: s
    draw: str = "uniform"  #: how the magnitudes are drawn in the range (`STRENGTH_DRAWS`)


class Scenario(NamedTuple):
    """One explicit scenario (scenario mode)."""

    state: str
    strength: float  #: signed strength (0 for "fn")
    onset: float
    profile: str
    ramp: float
    runs: int


class RunSpec(NamedTuple):
    """The labels of every run of a campaign (arrays of length ``n_runs``)."""

    state: np.ndarray
    strength: np.ndarray
    onset: np.ndarray
    profile: np.ndarray
    ramp: np.ndarray


def draw_magnitudes(spec: FaultSpec, n: int, rng: np.random.Generator) -> np.ndarray:
    """The magnitudes of ``n`` runs of one fault, drawn in ``spec.strength`` as ``spec.draw`` says.

    ``"uniform"``: independent uniform draws. ``"stratified"``: the range cut into ``n`` equal
    slices, one uniform draw in each, in a random order (a Latin hypercube in one dimension), so
    that a few runs cannot all miss the strong (or the weak) end of the range. A range of one
    value gives that value ``n`` times, whatever the draw.
    """
    low, high = spec.strength
    if high <= low:
        return np.full(n, low)
    if spec.draw == "uniform":
        return rng.uniform(low, high, n)
    if spec.draw != "stratified":
        raise ValueError(f"unknown strength draw {spec.draw!r} (one of {STRENGTH_DRAWS})")
    slices = rng.permutation(n) + rng.uniform(0.0, 1.0, n)
    return low + (high - low) * slices / n


@dataclasses.dataclass(frozen=True)
class Campaign:
    """A validated simulation campaign (immutable); build it with
    :func:`~bayes_fdi.campaigns.load_campaign`.

    Attributes mirror the TOML schema of `bayes_fdi.campaigns.parsing`. ``faults`` maps every
    fault ``f1..f19`` to its resolved :class:`FaultSpec` (defaults merged with overrides);
    ``scenarios`` is empty in state mode; ``excitation`` is empty unless ``source``
    is ``"excitation"``. ``raw`` is the validated TOML table (for provenance and
    :meth:`replace`); ``path`` the file it came from, if any.
    """

    name: str
    seed: int
    duration: int
    source: str
    states: tuple[str, ...]
    runs_per_state: int
    batch_size: int
    inputs: Mapping[str, Any]
    faults: Mapping[str, FaultSpec]
    scenarios: tuple[Scenario, ...]
    description: str = ""
    #: ``source = "excitation"``: the parsed ``[excitation]`` table
    #: (`bayes_fdi.campaigns.excitation.parse_excitation`); empty otherwise
    excitation: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    raw: Mapping[str, Any] = dataclasses.field(default_factory=dict, repr=False, compare=False)
    path: str | None = None

    @property
    def n_runs(self) -> int:
        """Number of runs the campaign simulates."""
        if self.scenarios:
            return sum(s.runs for s in self.scenarios)
        return len(self.states) * self.runs_per_state

    def replace(self, **overrides: Any) -> Campaign:
        """A validated copy with keys overridden, e.g. ``replace(runs_per_state=2)``.

        Keys are those of the schema; ``campaign.`` keys may be given bare (``duration=60``),
        others dotted via a mapping: ``replace(**{"faults.strength": [0.6, 0.7]})``.
        """
        from bayes_fdi.campaigns.parsing import apply_overrides, parse_campaign, thaw

        return parse_campaign(apply_overrides(thaw(self.raw), overrides), path=self.path)

    def run_specs(self, seed: int | None = None) -> RunSpec:
        """Draw the labels of every run (strengths are random in state mode).

        Parameters
        ----------
        seed
            Overrides the campaign's seed. The draw uses its own stream of the seed, so it does not
            depend on ``batch_size``.
        """
        from bayes_fdi.campaigns.parsing import check_seed

        seed = self.seed if seed is None else check_seed(seed, "seed")
        rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[0])
        rows: list[tuple[str, float, float, str, float]] = []
        if self.scenarios:
            for s in self.scenarios:
                rows.extend([(s.state, s.strength, s.onset, s.profile, s.ramp)] * s.runs)
        else:
            for state in self.states:
                n = self.runs_per_state
                if state == "fn":
                    rows.extend([("fn", 0.0, 0.0, "abrupt", 0.0)] * n)
                    continue
                spec = self.faults[state]
                magnitude = draw_magnitudes(spec, n, rng)
                for m in magnitude:
                    rows.append(
                        (state, spec.direction * float(m), spec.onset, spec.profile, spec.ramp)
                    )
        state, strength, onset, profile, ramp = zip(*rows, strict=True)
        return RunSpec(
            np.array(state, dtype=str),
            np.array(strength, dtype=np.float64),
            np.array(onset, dtype=np.float64),
            np.array(profile, dtype=str),
            np.array(ramp, dtype=np.float64),
        )
