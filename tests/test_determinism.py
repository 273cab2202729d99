"""Same seed, same numbers on any BLAS code path and thread count.

``bayes-fdi reproduce`` runs in subprocesses whose environment selects another code path of the
BLAS libraries (torch's MKL: ``MKL_CBWR``; numpy's and scipy's OpenBLAS:
``OPENBLAS_CORETYPE``) or another thread count; every figure the report prints (the Markdown of
``report.md`` rendered from ``results.json`` with the wall-clock times zeroed, and each
calibration report) must come out identical, digit for digit. The last bits of a matrix product
differ between these code paths, so this fails whenever a discrete decision of the pipeline (a
relevance vector chosen, a k-means split, a kernel width, a recalibrator) amplifies rounding.

The default run compares the default code path on one thread with every other setting changed
at once (MKL AVX2 path, OpenBLAS Haswell kernels, two threads) on a small campaign; the slow
runs compare the settings one at a time and the ``--small`` paper campaigns.
"""

from __future__ import annotations

import difflib
import json
import subprocess
import sys
from pathlib import Path

import pytest
from blas_paths import EVERYTHING_ELSE, REFERENCE, blas_env
from tiny_campaign import CAMPAIGN, STATES

from bayes_fdi.campaigns.cache import load_or_simulate
from bayes_fdi.paper.report import render_report

SEED = 3
#: Keys of results.json that hold wall-clock times (or whether the cache was hit).
_TIMING = {"seconds", "simulate_seconds", "fit_seconds", "predict_seconds", "cached"}


def _scrub(obj):
    """``results.json`` with every wall-clock time zeroed (they are the only figures that vary)."""
    if isinstance(obj, dict):
        return {
            k: ({} if k == "timing" else 0 if k in _TIMING else _scrub(v)) for k, v in obj.items()
        }
    if isinstance(obj, list):
        return [_scrub(v) for v in obj]
    return obj


def printed_figures(out: Path) -> dict[str, str]:
    """Every text the run prints: its report (times zeroed) and each calibration report."""
    results = _scrub(json.loads((out / "results.json").read_text()))
    texts = {"report.md": render_report(results)}
    for path in sorted(out.glob("*-calibration/report.md")):
        texts[path.relative_to(out).as_posix()] = path.read_text()
    return texts


def assert_same_figures(a: Path, b: Path) -> None:
    fa, fb = printed_figures(a), printed_figures(b)
    assert sorted(fa) == sorted(fb)
    diffs = []
    for name, text in fa.items():
        if text != fb[name]:
            lines = difflib.unified_diff(
                text.splitlines(),
                fb[name].splitlines(),
                f"{a.name}/{name}",
                f"{b.name}/{name}",
                lineterm="",
            )
            diffs.append("\n".join(line[:300] for line in list(lines)[:40]))
    assert not diffs, "printed figures differ:\n" + "\n\n".join(diffs)


def run_reproduce(out: Path, env: dict[str, str], args: list[str]) -> Path:
    """``bayes-fdi reproduce --out out ARGS`` in a fresh interpreter with ``env`` added."""
    cmd = [sys.executable, "-m", "bayes_fdi", "reproduce", "--out", str(out), "--no-progress"]
    proc = subprocess.run(
        [*cmd, *args], env=blas_env(env), capture_output=True, text=True, timeout=1800, check=False
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The small campaign, simulated once into a cache both runs read."""
    tmp = tmp_path_factory.mktemp("determinism")
    toml = tmp / "tiny.toml"
    toml.write_text(CAMPAIGN.format(states=json.dumps(STATES)))
    load_or_simulate(toml, seed=SEED, cache_dir=tmp / "cache", progress=False)
    args = ["--seed", str(SEED), "--cache-dir", str(tmp / "cache"), "--campaign", str(toml)]
    args += ["--states", ",".join(STATES), "--dynamic-lags", ""]
    reference = run_reproduce(tmp / "reference", REFERENCE, args)
    return tmp, args, reference


def test_reproduce_identical_on_another_blas_code_path_and_thread_count(tiny):
    tmp, args, reference = tiny
    other = run_reproduce(tmp / "everything-else", EVERYTHING_ELSE, args)
    assert_same_figures(reference, other)


@pytest.mark.slow
@pytest.mark.parametrize(
    "env",
    [
        {"MKL_CBWR": "COMPATIBLE"},
        {"MKL_CBWR": "AVX2"},
        {"OPENBLAS_CORETYPE": "Haswell"},
        {"OMP_NUM_THREADS": "2", "MKL_NUM_THREADS": "2", "OPENBLAS_NUM_THREADS": "2"},
    ],
    ids=["mkl-compatible", "mkl-avx2", "openblas-haswell", "two-threads"],
)
def test_reproduce_identical_under_each_setting(tiny, env):
    tmp, args, reference = tiny
    name = "-".join(f"{k}={v}" for k, v in env.items())
    other = run_reproduce(tmp / name, REFERENCE | env, args)
    assert_same_figures(reference, other)


@pytest.mark.slow
def test_small_paper_campaigns_identical_across_code_paths(tmp_path_factory):
    """The paper's two campaigns (``--small``, dynamic models included) on three code paths."""
    tmp = tmp_path_factory.mktemp("determinism-small")
    args = ["--small", "--cache-dir", str(tmp / "cache")]
    reference = run_reproduce(tmp / "reference", REFERENCE, args)
    for name, env in (
        ("mkl-compatible", REFERENCE | {"MKL_CBWR": "COMPATIBLE"}),
        ("everything-else", EVERYTHING_ELSE),
    ):
        assert_same_figures(reference, run_reproduce(tmp / name, env, args))


def test_scrub_zeroes_only_times():
    results = {
        "seconds": 12.5,
        "datasets": {
            "x": {
                "rvm": {"accuracy": 0.9, "fit_seconds": 1.0, "predict_seconds": 0.1},
                "timing": {"test_residuals": 3.0},
                "campaign": {"cached": True, "simulate_seconds": 4.0, "campaign_sha256": "ab"},
            }
        },
    }
    assert _scrub(results) == {
        "seconds": 0,
        "datasets": {
            "x": {
                "rvm": {"accuracy": 0.9, "fit_seconds": 0, "predict_seconds": 0},
                "timing": {},
                "campaign": {"cached": 0, "simulate_seconds": 0, "campaign_sha256": "ab"},
            }
        },
    }
