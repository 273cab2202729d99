"""Normal (fault-free) models of the actuator's outputs X and F: the residual generators.

- `bayes_fdi.diagnosis.normal_models.inputs`: the inputs ``(CV, sqrt(P1 - P2), T1)`` and
  optional delayed commands.
- `bayes_fdi.diagnosis.normal_models.width_search`: the kernel-width searches (summed evidence
  over a grid; the paper's GA).
- `bayes_fdi.diagnosis.normal_models.static`: `NormalModels`, the paper's static RVR models of
  the offline diagnoser.
- `bayes_fdi.diagnosis.normal_models.fit_steps`: the training samples and the kernel width of
  each output, steps of `NormalModels.fit`.
- `bayes_fdi.diagnosis.normal_models.dynamic`: `DynamicNormalModels`, the online diagnoser's
  models (position from the command's dynamics, flow from the predicted position), an online
  component with ``update``/``run`` and its own state;
  `bayes_fdi.diagnosis.normal_models.dynamic_kernel` their inputs and compiled per-second
  predictor; `bayes_fdi.diagnosis.normal_models.physics_inputs` their opt-in physics inputs
  (the command's lag, the valve law); `bayes_fdi.diagnosis.normal_models.residuals` their
  standardised residuals; `bayes_fdi.diagnosis.normal_models.speed_factors` the calibration of their
  predictive standard deviations by command speed;
  `bayes_fdi.diagnosis.normal_models.training_size` the learning curve that chooses how many
  samples they are fitted on.
- `bayes_fdi.diagnosis.normal_models.interval_calibration` and `.std_scaler`: honest
  predictive standard deviations of the static models (cross-fitted factors).
- `bayes_fdi.diagnosis.normal_models.kernel_ridge`: the SVM baseline's kernel ridge models.
- `bayes_fdi.diagnosis.normal_models.compiled`: the compiled one-sample predictor of a fitted
  RVR.

May import `bayes_fdi.rvm`, `bayes_fdi.datasets`, `bayes_fdi.diagnosis.component_state`, the
foundation and (for the physics inputs' valve law) `bayes_fdi.actuator`.
"""

from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.normal_models.inputs import (
    MODEL_INPUTS,
    NegativePressureDropWarning,
    input_names,
    model_inputs,
)
from bayes_fdi.diagnosis.normal_models.kernel_ridge import KernelRidgeRegressor
from bayes_fdi.diagnosis.normal_models.static import NormalModels
from bayes_fdi.diagnosis.normal_models.std_scaler import StdScaler
from bayes_fdi.diagnosis.normal_models.training_size import (
    TrainingCurvePoint,
    TrainingSize,
    choose_training_size,
)
from bayes_fdi.diagnosis.normal_models.width_search import (
    WIDTH_GRID,
    EvidenceGridResult,
    GAResult,
    evidence_grid_search,
    genetic_width_search,
)

__all__ = [
    "MODEL_INPUTS",
    "WIDTH_GRID",
    "DynamicNormalModels",
    "EvidenceGridResult",
    "GAResult",
    "KernelRidgeRegressor",
    "NegativePressureDropWarning",
    "NormalModels",
    "StdScaler",
    "TrainingCurvePoint",
    "TrainingSize",
    "choose_training_size",
    "evidence_grid_search",
    "genetic_width_search",
    "input_names",
    "model_inputs",
]
