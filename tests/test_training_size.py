"""How many samples the dynamic normal models are fitted on: the learning curve's rule, its held-out
scoring, and the fit that uses it (``max_train_samples="auto"``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from bayes_fdi import model_files
from bayes_fdi.diagnosis.normal_models import (
    DynamicNormalModels,
    TrainingSize,
    choose_training_size,
)
from bayes_fdi.diagnosis.normal_models.training_size import (
    MIN_GAIN,
    held_out_split,
    log_predictive_density,
)


def table_score(table):
    calls = []

    def score(rows):
        calls.append(rows)
        return table[rows]

    return score, calls


def test_small_data_take_every_row_without_a_curve():
    score, calls = table_score({})
    assert choose_training_size(score, 1500, 1800) == TrainingSize(1800, 1800, ())
    assert choose_training_size(score, 1900, 2400) == TrainingSize(2000, 2400, ())
    assert calls == []


def test_the_curve_stops_at_the_first_doubling_that_gains_too_little():
    table = {2000: (1.0, 2.0), 4000: (1.0, 2.02), 8000: (1.001, 2.021)}
    score, calls = table_score(table)
    size = choose_training_size(score, 20_000, 25_000, max_rows=8000)
    # 2000 -> 4000 gains 0.02 nats in F (>= 0.005): kept; 4000 -> 8000 gains 0.001: stop
    assert calls == [2000, 4000, 8000]
    assert size.rows == 4000 and size.available == 25_000
    assert [p.rows for p in size.curve] == [2000, 4000, 8000]
    assert size.curve[1].lpd_f == 2.02


def test_the_curve_takes_all_the_data_when_its_last_point_still_gains():
    # 1 h of data: 2880 rows fit, 720 score; the last point is the whole fitting part
    score, calls = table_score({2000: (1.0, 1.0), 2880: (1.0 + 2 * MIN_GAIN, 1.0)})
    size = choose_training_size(score, 2880, 3600)
    assert calls == [2000, 2880]
    assert size.rows == 3600


def test_the_curve_is_bounded_and_a_nan_score_stops_it():
    gains = {2000: (0.0, 0.0), 4000: (1.0, 0.0), 6000: (1.5, 0.0), 8000: (2.0, 0.0)}
    assert choose_training_size(table_score(gains)[0], 50_000, 60_000).rows == 4000  # MAX_ROWS
    assert choose_training_size(table_score(gains)[0], 50_000, 60_000, max_rows=8000).rows == 8000
    assert choose_training_size(table_score(gains)[0], 50_000, 60_000, max_rows=6000).rows == 6000
    nan = {2000: (0.0, 0.0), 4000: (np.nan, np.nan), 8000: (5.0, 5.0)}
    score, calls = table_score(nan)
    assert choose_training_size(score, 50_000, 60_000, max_rows=8000).rows == 2000
    assert calls == [2000, 4000]


def test_describe_says_the_rows_and_the_curve():
    size = TrainingSize(4000, 21_600, choose_training_size(
        table_score({2000: (4.3, 3.3), 4000: (4.31, 3.31), 8000: (4.3105, 3.3105)})[0],
        20_000, 21_600, max_rows=8000).curve)  # fmt: skip
    text = size.describe()
    assert text.startswith("fitted on 4000 of 21600 healthy samples, chosen by a learning curve")
    assert "2000: X 4.300, F 3.300; 4000: X 4.310" in text
    assert (
        TrainingSize(1800, 1800).describe()
        == "fitted on 1800 of 1800 healthy samples (all of them)"
    )
    assert TrainingSize(300, None).describe() == "fitted on 300 healthy samples"


def test_log_predictive_density_is_the_gaussian_log_density():
    rng = np.random.default_rng(4)
    y, mean, std = rng.normal(size=50), rng.normal(size=50), rng.uniform(0.1, 2.0, 50)
    y[3] = np.nan
    ok = np.isfinite(y)
    expected = stats.norm.logpdf(y[ok], mean[ok], std[ok]).mean()
    assert log_predictive_density(y, mean, std) == pytest.approx(expected, rel=1e-13)
    assert np.isnan(log_predictive_density(np.full(3, np.nan), mean[:3], std[:3]))


def test_held_out_split_scores_every_fifth_minute_of_every_run():
    finite = np.ones(2 * 600, dtype=bool)
    finite[250] = False  # inside a scored minute
    fit, held = held_out_split(finite, 2, 600)
    minute = (np.arange(1200) % 600) // 60
    expected = np.flatnonzero(np.isin(minute, [4, 9]))
    assert held.tolist() == [i for i in expected if i != 250]
    assert fit.size == 1200 - expected.size and not np.isin(fit, expected).any()


@pytest.fixture(scope="module")
def healthy():
    from bayes_fdi.actuator import simulate
    from bayes_fdi.actuator.excitation import level_loop_inputs

    return simulate(level_loop_inputs(2, 1500, seed=5).drop_vars("level"), seed=5)


def light(rows):
    return DynamicNormalModels(
        x_widths=(4.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=rows,
        calibration_folds=2, random_state=0,
    )  # fmt: skip


def test_auto_on_small_data_is_the_fixed_fit(healthy):
    short = healthy.isel(run=[0], time=slice(0, 600))
    auto, fixed = light("auto").fit(short), light(2000).fit(short)
    assert auto.training_size_ == TrainingSize(600, 600, ())
    a, b = auto.predict(short), fixed.predict(short)
    for name in ("X_hat", "X_hat_std", "F_hat", "F_hat_std"):
        np.testing.assert_array_equal(a[name].values, b[name].values)


@pytest.mark.slow
def test_auto_follows_its_curve_and_keeps_it_in_the_model_file(healthy, tmp_path):
    models = light("auto").fit(healthy)
    size = models.training_size_
    assert size.available == 3000
    assert [p.rows for p in size.curve] == [2000, 2400]  # 5 of each run's 25 minutes score
    gain = max(size.curve[1].lpd_x - size.curve[0].lpd_x, size.curve[1].lpd_f - size.curve[0].lpd_f)
    assert size.rows == (3000 if gain >= MIN_GAIN else 2000)
    assert models.n_train_samples_ == size.rows
    # the held-out densities are those of the normal models' own predictions: finite, and
    # about the sensors' noise level (X, F noise std about 0.2 % to 1 % of full scale)
    for p in size.curve:
        assert 2.0 < p.lpd_x < 7.0 and 2.0 < p.lpd_f < 7.0
    path = tmp_path / "models.npz"
    model_files.save(models, path)
    assert model_files.load(path).training_size_ == size


def test_auto_is_a_valid_parameter_and_other_strings_are_not(healthy):
    with pytest.raises(ValueError, match='max_train_samples must be an integer >= 10 or "auto"'):
        light("all").fit(healthy)
