"""Datasets: labelled actuator runs (``run`` x ``time`` x channels) and the readers that make them.

- `bayes_fdi.datasets.format`: the one dataset type used throughout the project (dims ``run`` and
  ``time``, channels ``CV, P1, P2, T1, X, F`` normalised as DABLib does, per-run labels), with
  `make_dataset`, `validate_dataset`, `save_dataset` and `load_dataset` (netCDF).
- `bayes_fdi.datasets.lublin`: the real Lublin hour shipped with the package, the benchmark's day
  files and the table of the real fault events.
- `bayes_fdi.datasets.readers`: recordings from CSV, MATLAB, netCDF and day files, in any declared
  units, on the model's 1-s grid (`read_recording`; `bayes_fdi.datasets.time_grid`: time
  columns in seconds, resampling onto the grid and the gaps; `bayes_fdi.datasets.csv_columns`:
  CSV files read in chunks; `bayes_fdi.datasets.units`: units, and values implausible in them).
- `bayes_fdi.datasets.plotting`: signal plots of chosen runs (the ``bayes-fdi plot`` command).
"""

from bayes_fdi.datasets.format import (
    CHANNELS,
    INPUT_CHANNELS,
    MEASUREMENT_FAULTS,
    OUTPUT_CHANNELS,
    STATES,
    load_dataset,
    make_dataset,
    save_dataset,
    state_order,
    validate_dataset,
)
from bayes_fdi.datasets.lublin import (
    LUBLIN_FAULT_EVENTS,
    find_gaps,
    load_lublin_day,
    load_lublin_example,
)
from bayes_fdi.datasets.readers import read_recording

__all__ = [
    "CHANNELS",
    "INPUT_CHANNELS",
    "LUBLIN_FAULT_EVENTS",
    "MEASUREMENT_FAULTS",
    "OUTPUT_CHANNELS",
    "STATES",
    "find_gaps",
    "load_dataset",
    "load_lublin_day",
    "load_lublin_example",
    "make_dataset",
    "read_recording",
    "save_dataset",
    "state_order",
    "validate_dataset",
]
