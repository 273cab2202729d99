"""Saved `~bayes_fdi.diagnosis.normal_models.dynamic.DynamicNormalModels` of older model files
in today's layout (the class's ``upgrade_model_file`` hook, which the model-file loader calls).

- bayes_fdi 0.1.0 held the compiled kernel's arguments as ``_lean`` and ``_kernel_args``; today
  they are ``params_``, rebuilt from the regressors;
- format <= 4 fitted the std factors by maximum likelihood (``std_coverage=None``);
- format <= 8 had no physics inputs;
- format <= 10 had a command lag without speed limits (``lag_speed_limits=False``) and a
  position model that learnt X itself (``lag_as_mean=False``);
- format <= 11 had a flow model that learnt F itself (``law_as_mean=False``) and std factors
  by command speed (``std_bins="speed"``);
- models saved before the learning curve record their rows as a `TrainingSize` without one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bayes_fdi.diagnosis.normal_models.training_size import TrainingSize

__all__ = ["upgrade_dynamic_models"]


def upgrade_dynamic_models(cls: type, data: dict[str, Any]) -> dict[str, Any]:
    """The saved attributes ``data`` of a ``cls`` (`DynamicNormalModels`) in today's layout."""
    data = {k: v for k, v in data.items() if k not in ("_lean", "_kernel_args")}
    data.setdefault("std_coverage", None)  # before the parameter: maximum likelihood
    data.setdefault("physics_inputs", ())  # format <= 8
    data.setdefault("lag_speed_limits", False)  # format <= 10: a lag without speed limits
    data.setdefault("lag_as_mean", False)  # format <= 10: the position model learnt X
    data.setdefault("law_as_mean", False)  # format <= 11: the flow model learnt F
    data.setdefault("std_bins", "speed")  # format <= 11: std factors by command speed
    if "regressors_" in data:  # fitted without physics inputs
        data.update({"command_lag_": None, "valve_law_": np.empty(0)} | data)
        data.setdefault("novelty_reference_", np.empty((0, 0)))
    if "regressors_" in data and "training_size_" not in data:  # before the curve
        data["training_size_"] = TrainingSize(int(data.get("n_train_samples_", 0)), None)
    if "regressors_" in data and "params_" not in data:
        models = cls.__new__(cls)
        models.__dict__.update(data)
        data["params_"] = models._kernel_params(data["regressors_"]["X"], data["regressors_"]["F"])
    return data
