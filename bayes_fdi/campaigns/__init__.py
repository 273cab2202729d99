"""Simulation campaigns: declarative TOML files (``sim/``) turned into labelled datasets.

- `bayes_fdi.campaigns.spec`: the immutable `Campaign` and the constants of its schema.
- `bayes_fdi.campaigns.parsing`: the campaign file's schema and its validation
  (`load_campaign`, `parse_campaign`).
- `bayes_fdi.campaigns.simulation`: `simulate_campaign` (and the ``bayes-fdi simulate``
  command).
- `bayes_fdi.campaigns.shipped`: the campaign files shipped with the package.
- `bayes_fdi.campaigns.cache`: campaigns simulated once and cached as netCDF.

Library code: may import `bayes_fdi.actuator`, `bayes_fdi.datasets` and the foundation
(`atomic`, `memory`, `progress`, `cli_arguments`, `distributed`).
"""

from bayes_fdi.campaigns.parsing import load_campaign, parse_campaign
from bayes_fdi.campaigns.simulation import simulate_campaign
from bayes_fdi.campaigns.spec import Campaign, CampaignError

__all__ = ["Campaign", "CampaignError", "load_campaign", "parse_campaign", "simulate_campaign"]
