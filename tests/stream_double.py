"""A small stand-in for the online diagnoser (the stream of ``OnlineDiagnoser.run``, listed in
``docs/online.md``), for the tests of the recording pipeline only: it produces every variable of
the decision stream and carries its stream state across time chunks
(``run(chunk, state=..., return_state=True)``).

Linear normal models of X and F on (1, CV, CV one second earlier, sqrt(P1 - P2), T1), fitted by
least squares on fault-free runs; a one-sided CUSUM of each absolute standardised residual
(capped at twice the threshold) with hysteresis (on above ``threshold``, off when both sums are
back to 0); two isolation groups by which sum is larger. A second with a NaN channel is BLIND:
no decision, the sums are held.
"""

from __future__ import annotations

import json

import numpy as np
import xarray as xr
from sklearn.base import BaseEstimator

from bayes_fdi import model_files

X_GROUP = ("f1", "f7", "f10")
F_GROUP = ("f17", "f18", "f19")
FAULTS = tuple(f"f{i}" for i in range(1, 20))
CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


def _design(rec: dict[str, np.ndarray], previous_cv: np.ndarray) -> np.ndarray:
    cv = rec["CV"]
    lag = np.concatenate([previous_cv[:, None], cv[:, :-1]], axis=1)
    dp = np.sqrt(np.abs(rec["P1"] - rec["P2"]))
    return np.stack([np.ones_like(cv), cv, lag, dp, rec["T1"]], axis=-1)


def _arrays(ds: xr.Dataset) -> dict[str, np.ndarray]:
    if "run" not in ds.dims:
        ds = ds.expand_dims(run=[0])
    return {
        c: np.asarray(ds[c].transpose("run", "time").values, dtype=np.float64) for c in CHANNELS
    }


@model_files.register_persistable
class StreamDouble(BaseEstimator):
    """``fit(normal_runs, fault_runs=None)``, ``run(recording, state=None, return_state=False)``."""

    def __init__(self, drift: float = 2.0, threshold: float = 8.0) -> None:
        self.drift = drift
        self.threshold = threshold

    def fit(self, normal_runs: xr.Dataset, fault_runs: xr.Dataset | None = None):
        rec = _arrays(normal_runs)
        a = _design(rec, rec["CV"][:, 0]).reshape(-1, 5)
        ok = np.isfinite(a).all(axis=1)
        self.coef_, self.std_ = {}, {}
        for c in ("X", "F"):
            y = rec[c].reshape(-1)
            good = ok & np.isfinite(y)
            coef, *_ = np.linalg.lstsq(a[good], y[good], rcond=None)
            self.coef_[c] = coef
            self.std_[c] = float(np.std(y[good] - a[good] @ coef))
        self.groups_ = (X_GROUP, F_GROUP)
        self.n_fault_runs_ = 0 if fault_runs is None else int(fault_runs.sizes["run"])
        return self

    def initial_state(self, recording: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        n = recording["CV"].shape[0]
        return {
            "S_X": np.zeros(n),
            "S_F": np.zeros(n),
            "DD": np.zeros(n, dtype=bool),
            "CV": recording["CV"][:, 0].copy(),
        }

    def run(self, recording: xr.Dataset, state=None, return_state: bool = False):
        rec = _arrays(recording)
        state = (
            self.initial_state(rec) if state is None else {k: v.copy() for k, v in state.items()}
        )
        n_runs, n_t = rec["CV"].shape
        a = _design(rec, state["CV"])
        blind = ~np.all([np.isfinite(rec[c]) for c in CHANNELS], axis=0)
        out: dict[str, np.ndarray] = {}
        r = {}
        for c in ("X", "F"):
            hat = a @ self.coef_[c]
            r[c] = (rec[c] - hat) / self.std_[c]
            out[f"{c}_hat"], out[f"{c}_hat_std"] = hat, np.full_like(hat, self.std_[c])
            out[f"r_{c}"] = r[c]
        stat = {c: np.empty((n_runs, n_t)) for c in ("X", "F")}
        dd = np.empty((n_runs, n_t), dtype=bool)
        for t in range(n_t):
            ok = ~blind[:, t]
            for c in ("X", "F"):
                s = np.clip(
                    state[f"S_{c}"] + np.abs(r[c][:, t]) - self.drift, 0.0, 2 * self.threshold
                )
                state[f"S_{c}"] = np.where(ok, s, state[f"S_{c}"])
                stat[c][:, t] = state[f"S_{c}"]
            high = np.maximum(state["S_X"], state["S_F"]) > self.threshold
            cleared = (state["S_X"] == 0) & (state["S_F"] == 0)
            state["DD"] = np.where(ok, high | (state["DD"] & ~cleared), state["DD"])
            dd[:, t] = state["DD"] & ok
        state["CV"] = rec["CV"][:, -1].copy()
        share = stat["F"] / np.maximum(stat["X"] + stat["F"], 1e-12)
        group_proba = np.stack([1.0 - share, share], axis=-1)
        group_proba[~dd] = np.nan
        indicated = np.zeros((n_runs, n_t, 2), dtype=bool)
        indicated[..., 0] = dd & (share <= 0.5)
        indicated[..., 1] = dd & (share > 0.5)
        fault_proba = np.full((n_runs, n_t, len(FAULTS)), np.nan)
        for g, members in enumerate((X_GROUP, F_GROUP)):
            for f in members:
                fault_proba[..., FAULTS.index(f)] = group_proba[..., g] / len(members)
        labels = np.array(["|".join(X_GROUP), "|".join(F_GROUP)])
        best = np.nanargmax(np.where(dd[..., None], group_proba, 0.0), axis=-1)
        top = np.take_along_axis(group_proba, best[..., None], axis=-1)[..., 0]
        state_label = np.where(dd, np.where(top > 0.9, labels[best], "unknown"), "fn")
        probability = np.where(dd & (top > 0.9), top, np.nan)
        status = np.where(blind, "BLIND", np.where(dd, "BLURRED", "CLEAR"))
        status = np.where(~blind & ~dd & (np.abs(r["X"]) > 4), "DAZZLED", status)
        out.update(stat_X=stat["X"], stat_F=stat["F"])
        for c in ("X", "F"):
            out[f"VMV_{c}"] = np.where(dd, out[f"{c}_hat"], rec[c])
            out[f"VU_{c}"] = 1.96 * out[f"{c}_hat_std"]
        coords = {"run": np.arange(n_runs), "time": recording["time"].values,
                  "group": labels, "fault": list(FAULTS)}  # fmt: skip
        if "run" in recording.dims:
            coords["run"] = recording["run"].values
        rt = ("run", "time")
        ds = xr.Dataset(
            {
                **{k: (rt, v) for k, v in out.items()},
                "DD": (rt, dd),
                "FFID": (rt, ~dd & ~blind),
                "indicated": ((*rt, "group"), indicated),
                "group_proba": ((*rt, "group"), group_proba),
                "fault_proba": ((*rt, "fault"), fault_proba),
                "state": (rt, state_label.astype(object)),
                "probability": (rt, probability),
                "status": (rt, status.astype(object)),
            },
            coords=coords,
            attrs={
                "groups": json.dumps({labels[0]: list(X_GROUP), labels[1]: list(F_GROUP)}),
                "undetectable": json.dumps(["f14"]),
            },
        )
        return (ds, state) if return_state else ds

    def save(self, path):
        return model_files.save(self, path)

    @classmethod
    def load(cls, path):
        return model_files.load(path, expected=cls)
