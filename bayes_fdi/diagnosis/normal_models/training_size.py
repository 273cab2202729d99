"""How many samples the dynamic normal models are fitted on: a learning curve on held-out time.

An RVR fit costs more than linearly in its rows, and the normal models of a long recording
gain little from all of them: on five simulated hours of a level loop scored on a sixth,
doubling the rows from 2000 to 4000 raised the held-out log predictive density by 0.014 (X)
and 0.010 (F) nats per sample and from 4000 to 8000 by 0.0015 and 0.0012, at 2.5 times the
fit's CPU time per doubling; on 24 hours, 2000 to 4000 gained 0.118 (X) and 0.110 (F) nats at
13 times the CPU time. `choose_training_size` walks that curve: every fifth minute of each
run scores (`held_out_split`), the rest fits, the rows double from `FIRST_ROWS` while a doubling
gains at least `MIN_GAIN` nats per sample in X or F, and `MAX_ROWS` bounds the fit's cost.

`MIN_GAIN` (0.005 nats) is a change of 0.5 % in the predictive standard deviation: below the
precision of the standard deviations' own calibration on a few thousand out-of-fold residuals
(the relative standard error of a standard deviation estimated from ``n`` samples is about
``1 / sqrt(2 n)``, 1.6 % at ``n = 2000``), so a smaller gain cannot change what the detector
sees. Written by hand: a learning curve over one estimator's private fit step, which
scikit-learn's ``learning_curve`` (cross-validated scores of whole estimators) does not give.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "FIRST_ROWS",
    "HELD_OUT_SHARE",
    "MAX_ROWS",
    "MIN_GAIN",
    "TrainingCurvePoint",
    "TrainingSize",
    "choose_training_size",
    "held_out_split",
    "learning_curve_size",
    "log_predictive_density",
]

#: Rows of the curve's first fit (and of every fit on smaller data: all rows, no curve).
FIRST_ROWS = 2000
#: The most rows a fit takes: an RVR fit's cost grows about tenfold per doubling here
#: (24 simulated hours of a level loop: 8.2 CPU s for the curve's fit of 2000 rows, 110.6 s for
#: 4000), and the final fit and each cross-fit fold pay it again.
MAX_ROWS = 4000
#: Least gain of a doubling (nats per held-out sample, X or F) for the curve to go on.
MIN_GAIN = 0.005
#: Share of each run's time that scores the curve's fits: every fifth block of
#: `HELD_OUT_BLOCK` seconds (longer than the loops' settling, so that a scored second's
#: neighbours in time are mostly scored too).
HELD_OUT_SHARE = 0.2
HELD_OUT_BLOCK = 60


class TrainingCurvePoint(NamedTuple):
    """One fit of the learning curve."""

    rows: int  #: rows of the fit
    lpd_x: float  #: mean log predictive density of X on the held-out time (nats per sample)
    lpd_f: float  #: the same for F


class TrainingSize(NamedTuple):
    """How many samples the normal models were fitted on, and why."""

    rows: int  #: rows of the fits
    available: int | None  #: complete fault-free samples of the data (None: not recorded)
    curve: tuple[TrainingCurvePoint, ...] = ()  #: the learning curve (empty: not drawn)

    def describe(self) -> str:
        """One line for a report: the rows, and the learning curve when one chose them."""
        if self.available is None:
            return f"fitted on {self.rows} healthy samples"
        text = f"fitted on {self.rows} of {self.available} healthy samples"
        if not self.curve:
            return text + (" (all of them)" if self.rows >= self.available else " (a fixed subset)")
        points = "; ".join(f"{p.rows}: X {p.lpd_x:.3f}, F {p.lpd_f:.3f}" for p in self.curve)
        return (
            f"{text}, chosen by a learning curve on held-out time (rows: mean log predictive "
            f"density in nats; a doubling is kept when it gains at least {MIN_GAIN} in X or F): "
            + points
        )


def held_out_split(finite: np.ndarray, n_runs: int, n_times: int) -> tuple[np.ndarray, np.ndarray]:
    """Row indices (of the flattened ``run x time`` grid) that fit and that score the curve.

    Time is cut into blocks of `HELD_OUT_BLOCK` seconds and every fifth block of every run
    (`HELD_OUT_SHARE`) scores, the rest fits: the scored seconds lie among the fitted ones, so
    the curve measures what more rows add where the data are, not an extrapolation to an
    operating point only the end of the recording reached. Only ``finite`` rows.
    """
    every = round(1 / HELD_OUT_SHARE)
    block = np.arange(n_times) // HELD_OUT_BLOCK
    late = np.broadcast_to(block % every == every - 1, (n_runs, n_times)).ravel()
    return np.flatnonzero(finite & ~late), np.flatnonzero(finite & late)


def log_predictive_density(y: np.ndarray, mean: np.ndarray, std: np.ndarray) -> float:
    """Mean Gaussian log density of ``y`` under ``N(mean, std^2)`` over the finite samples
    (nats per sample); NaN when none is finite."""
    ok = np.isfinite(y) & np.isfinite(mean) & np.isfinite(std) & (std > 0)
    if not ok.any():
        return float("nan")
    z = (y[ok] - mean[ok]) / std[ok]
    return float(np.mean(-0.5 * z**2 - np.log(std[ok]) - 0.5 * np.log(2.0 * np.pi)))


def choose_training_size(
    score: Callable[[int], tuple[float, float]],
    n_fit: int,
    n_all: int,
    *,
    first: int = FIRST_ROWS,
    max_rows: int = MAX_ROWS,
    min_gain: float = MIN_GAIN,
) -> TrainingSize:
    """The rows the normal models are fitted on, and the learning curve that chose them.

    Parameters
    ----------
    score
        ``score(rows)`` fits on ``rows`` of the fitting part and returns the held-out mean log
        predictive densities of X and F.
    n_fit, n_all
        Rows of the fitting part, and of all the data.
    first, max_rows, min_gain
        `FIRST_ROWS`, `MAX_ROWS`, `MIN_GAIN`.

    Returns
    -------
    TrainingSize
        ``min(n_all, first)`` rows when the data or the fitting part have at most ``first``
        rows (no curve); else the rows of the last doubling that gained at least ``min_gain``
        in X or F, or all rows (at most ``max_rows``) when the curve's last point, all of the
        fitting part, still gained.
    """
    if n_all <= first or n_fit <= first:
        return TrainingSize(min(n_all, first), n_all)
    sizes = [first]
    while sizes[-1] < min(n_fit, max_rows):
        sizes.append(min(2 * sizes[-1], n_fit, max_rows))
    curve: list[TrainingCurvePoint] = []
    chosen = first
    for rows in sizes:
        curve.append(TrainingCurvePoint(rows, *map(float, score(rows))))
        if len(curve) == 1:
            continue
        gain = max(curve[-1].lpd_x - curve[-2].lpd_x, curve[-1].lpd_f - curve[-2].lpd_f)
        if not gain >= min_gain:
            break
        chosen = rows
    if chosen == n_fit:  # every row of the fitting part still helped: take all the data
        chosen = min(n_all, max_rows)
    return TrainingSize(int(chosen), int(n_all), tuple(curve))


def learning_curve_size(
    runs: Any,
    y: dict[str, np.ndarray],
    finite: np.ndarray,
    fit_rows: Callable[[np.ndarray, int], tuple[Any, Any]],
    predict: Callable[[Any, Any], np.ndarray],
) -> TrainingSize:
    """`choose_training_size` scored on the held-out part of fault-free runs (`held_out_split`).

    Parameters
    ----------
    runs
        The runs (sizes ``run`` and ``time``).
    y
        ``{"X": (n,), "F": (n,)}`` the measured outputs, flattened ``run x time``.
    finite
        ``(n,)`` the complete samples.
    fit_rows
        ``fit_rows(rows, size)`` fits the position and flow models on ``size`` of ``rows``.
    predict
        ``predict(mx, mf)``: their ``(n_runs, n_times, >= 4)`` predictions of ``runs``
        (X_hat, its std, F_hat, its std first).
    """
    fit, held = held_out_split(finite, runs.sizes["run"], runs.sizes["time"])

    def score(n: int) -> tuple[float, float]:
        out = predict(*fit_rows(fit, n))
        out = out.reshape(-1, out.shape[-1])[held]
        lpd = log_predictive_density
        return lpd(y["X"][held], out[:, 0], out[:, 1]), lpd(y["F"][held], out[:, 2], out[:, 3])

    return choose_training_size(score, fit.size, int(finite.sum()))
