"""A test double of the online diagnoser (the stream of ``OnlineDiagnoser.run``), for tests only.

Linear normal models of X and F (least squares on fault-free runs), a two-sided CUSUM on the
standardised residuals with hysteresis, and a two-group isolation by which residual moved more
since the detection. It produces every variable of the decision stream, so the benchmark
harness can be tested without the real diagnoser.
"""

from __future__ import annotations

import json

import numpy as np
import xarray as xr
from sklearn.base import BaseEstimator

X_GROUP = ("f1", "f4", "f7", "f8", "f10", "f11", "f12", "f13", "f15", "f16")
F_GROUP = ("f2", "f3", "f5", "f6", "f9", "f17", "f18", "f19")
UNDETECTABLE = ("f14",)
FAULTS = tuple(f"f{i}" for i in range(1, 20))


def _features(ds: xr.Dataset) -> np.ndarray:
    cv = ds["CV"].transpose("run", "time").values
    lag = np.concatenate([cv[:, :1], cv[:, :-1]], axis=1)
    dp = np.sqrt(np.clip(ds["P1"].values - ds["P2"].values, 0.0, None))
    return np.stack([np.ones_like(cv), cv, lag, dp, ds["T1"].values], axis=-1)


class OnlineDouble(BaseEstimator):
    """Follows the contract: ``fit(normal_runs, fault_runs=None)``, ``run(recording)``."""

    def __init__(self, drift: float = 1.0, threshold: float = 12.0):
        self.drift = drift
        self.threshold = threshold

    def fit(self, normal_runs: xr.Dataset, fault_runs: xr.Dataset | None = None):
        a = _features(normal_runs).reshape(-1, 5)
        self.coef_ = {}
        self.std_ = {}
        for c in ("X", "F"):
            y = normal_runs[c].transpose("run", "time").values.reshape(-1)
            coef, *_ = np.linalg.lstsq(a, y, rcond=None)
            self.coef_[c] = coef
            self.std_[c] = float(np.std(y - a @ coef))
        self.groups_ = (X_GROUP, F_GROUP)
        return self

    def run(self, recording: xr.Dataset) -> xr.Dataset:
        if "run" not in recording.dims:
            recording = recording.expand_dims(run=[0])
        a = _features(recording)
        n_runs, n_t = a.shape[:2]
        out = {}
        r = {}
        for c in ("X", "F"):
            hat = a @ self.coef_[c]
            r[c] = (recording[c].transpose("run", "time").values - hat) / self.std_[c]
            out[f"{c}_hat"] = hat
            out[f"{c}_hat_std"] = np.full_like(hat, self.std_[c])
            out[f"r_{c}"] = r[c]
            out[f"VMV_{c}"] = hat
            out[f"VU_{c}"] = np.full_like(hat, 1.96 * self.std_[c])
        stat = {c: np.zeros((n_runs, n_t)) for c in ("X", "F")}
        dd = np.zeros((n_runs, n_t), dtype=bool)
        s = {c: np.zeros(n_runs) for c in ("X", "F")}
        on = np.zeros(n_runs, dtype=bool)
        since = np.zeros((n_runs, 2))
        count = np.zeros(n_runs)
        proba_x = np.full((n_runs, n_t), np.nan)
        for t in range(n_t):
            for c in ("X", "F"):
                s[c] = np.maximum(0.0, s[c] + np.abs(r[c][:, t]) - self.drift)
                stat[c][:, t] = s[c]
            level = np.maximum(s["X"], s["F"])
            on = np.where(on, level > 0.0, level > self.threshold)  # hysteresis
            dd[:, t] = on
            since = np.where(on[:, None], since + np.abs([r["X"][:, t], r["F"][:, t]]).T, 0.0)
            count = np.where(on, count + 1, 0)
            margin = (since[:, 0] - since[:, 1]) / np.maximum(count, 1)
            proba_x[:, t] = np.where(on, 1.0 / (1.0 + np.exp(-2.0 * margin)), np.nan)
        group_proba = np.stack([proba_x, 1.0 - proba_x], axis=-1)
        indicated = np.stack([dd & (proba_x >= 0.5), dd & (proba_x < 0.5)], axis=-1)
        fault_proba = np.full((n_runs, n_t, len(FAULTS)), np.nan)
        for g, members in enumerate((X_GROUP, F_GROUP)):
            for f in members:
                fault_proba[:, :, FAULTS.index(f)] = group_proba[:, :, g] / len(members)
        labels = ["|".join(X_GROUP), "|".join(F_GROUP)]
        top = np.nanmax(np.where(dd[..., None], group_proba, 0.0), axis=-1)
        state = np.where(dd, np.where(proba_x >= 0.5, labels[0], labels[1]), "fn")
        status = np.where(dd, np.where(top > 0.9, "BLURRED", "DAZZLED"), "CLEAR")
        dims = ("run", "time")
        data = {k: (dims, v) for k, v in out.items()}
        data.update(
            DD=(dims, dd),
            FFID=(dims, ~dd),
            indicated=((*dims, "group"), indicated),
            group_proba=((*dims, "group"), group_proba),
            fault_proba=((*dims, "fault"), fault_proba),
            state=(dims, state),
            probability=(dims, np.where(dd, top, np.nan)),
            status=(dims, status),
            stat_X=(dims, stat["X"]),
            stat_F=(dims, stat["F"]),
        )
        groups = {lab: list(m) for lab, m in zip(labels, (X_GROUP, F_GROUP), strict=True)}
        return xr.Dataset(
            data,
            coords={
                "run": recording["run"].values,
                "time": recording["time"].values,
                "group": labels,
                "fault": list(FAULTS),
            },
            attrs={"groups": json.dumps(groups), "undetectable": json.dumps(UNDETECTABLE)},
        )
