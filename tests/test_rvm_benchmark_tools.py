"""Tools of the RVM fit benchmark (benchmarks/rvm_fit.py): data, kernel mapping, ratios, table.

No timing is asserted here: speed targets live in the benchmark itself.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from benchmark_scripts import load_benchmark
from sklearn.metrics.pairwise import pairwise_kernels

bench = load_benchmark("rvm_fit")
worker = load_benchmark("rvm_worker")


def _row(method, n, cpu, rmse, *, status="ok", rmse_f=None, peak=100.0, base=50.0):
    return {
        "method": method,
        "n": n,
        "status": status,
        "fit_cpu_s": cpu,
        "fit_s": cpu * 1.5,
        "rmse": rmse,
        "rmse_f": rmse / 2 if rmse_f is None else rmse_f,
        "peak_rss_mb": peak,
        "rss_before_fit_mb": base,
        "n_rv": 30,
        "version": f"{method} 1.0",
    }


# ------------------------------------------------------------------------------------ data
def test_target_function_closed_form_points():
    X = np.array([[0.5, 0.0, 0.0], [0.0, 1.0, 1.0], [0.5, 1.0, 0.0], [-0.5, 0.0, -1.0]])
    # sin(pi/2) cos(0) = 1; 0 + 1/2; sin(pi/2) cos(pi/2) = 0; -1 + 1/2
    np.testing.assert_allclose(bench.target_function(X), [1.0, 0.5, 0.0, -0.5], atol=1e-15)
    with pytest.raises(ValueError, match="shape"):
        bench.target_function(np.zeros((4, 2)))


def test_make_data_seeded_shapes_noise_and_shared_test_set():
    a = bench.make_data(20000, 500, noise_std=0.1, seed=3)
    b = bench.make_data(20000, 500, noise_std=0.1, seed=3)
    c = bench.make_data(20000, 500, noise_std=0.1, seed=4)
    for key in ("X_train", "y_train", "X_test", "y_test"):
        np.testing.assert_array_equal(a[key], b[key])
    assert not np.array_equal(a["X_train"], c["X_train"])
    assert a["X_train"].shape == (20000, 3) and a["X_test"].shape == (500, 3)
    assert np.all(np.abs(a["X_train"]) <= 1.0)
    np.testing.assert_allclose(a["f_train"], bench.target_function(a["X_train"]))
    np.testing.assert_allclose(a["f_test"], bench.target_function(a["X_test"]))
    # noise: mean 0, std 0.1; the sample std of 20000 draws is within 3 % of 0.1 (~ 6 sigma)
    resid = a["y_train"] - a["f_train"]
    assert abs(resid.std() - 0.1) < 0.003 and abs(resid.mean()) < 0.003
    # the test set does not depend on the training size
    small = bench.make_data(100, 500, noise_std=0.1, seed=3)
    np.testing.assert_array_equal(small["X_test"], a["X_test"])
    np.testing.assert_array_equal(small["y_test"], a["y_test"])
    with pytest.raises(ValueError, match="positive"):
        bench.make_data(0)
    with pytest.raises(ValueError, match="noise_std"):
        bench.make_data(10, noise_std=float("nan"))


# ------------------------------------------------------------------- kernel width mapping
def test_sigma_to_gamma_matches_peer_kernel_call_and_definition():
    rng = np.random.default_rng(0)
    X, Z = rng.uniform(-1, 1, (40, 3)), rng.uniform(-1, 1, (25, 3))
    for sigma in (0.3, 0.5, 2.0):
        gamma = bench.sigma_to_gamma(sigma)
        # exactly the call made by fastrvm.RVR.fit/predict and sklearn_rvm.EMRVR._get_kernel
        peer = pairwise_kernels(Z, X, metric="rbf", filter_params=True, gamma=gamma)
        ours = bench.rbf_kernel_sigma(Z, X, sigma)
        np.testing.assert_allclose(peer, ours, rtol=1e-12, atol=1e-15)
        # definition: at distance sigma the kernel is exp(-1/2), at distance 2 sigma exp(-2)
        x0 = np.zeros((1, 3))
        pts = np.array([[sigma, 0.0, 0.0], [0.0, 2 * sigma, 0.0]])
        np.testing.assert_allclose(
            pairwise_kernels(x0, pts, metric="rbf", gamma=gamma)[0], np.exp([-0.5, -2.0])
        )
        # the worker passes the same gamma to every peer
        assert worker._gamma(sigma) == pytest.approx(gamma, rel=1e-15)
    with pytest.raises(ValueError, match="sigma"):
        bench.sigma_to_gamma(0.0)


def test_width_convention_of_bayes_fdi_rvr_matches_reference_kernel():
    from bayes_fdi.rvm import RVR

    data = bench.make_data(60, 30, seed=1)
    sigma = 0.5
    model = RVR(kernel="rbf", width=sigma, bias=True).fit(data["X_train"], data["y_train"])
    B = model.design_matrix(data["X_test"], basis="all").cpu().numpy()
    np.testing.assert_allclose(B[:, 0], 1.0)  # bias column first
    np.testing.assert_allclose(
        B[:, 1:], bench.rbf_kernel_sigma(data["X_test"], data["X_train"], sigma), atol=1e-12
    )


# ------------------------------------------------------------------------------- ratios
def test_add_ratios_against_fastest_and_most_accurate_successful_peer():
    rows = [
        _row("bayes_fdi", 500, 0.5, 0.110, rmse_f=0.050),
        _row("fastrvm", 500, 0.2, 0.112, rmse_f=0.060),
        _row("sklearn-rvm", 500, 4.0, 0.105, rmse_f=0.040),
        _row("sklearn-ard", 500, 0.01, 0.001, status="timeout"),  # failed: never the reference
        _row("bayes_fdi", 2000, 1.0, 0.1),
        _row("fastrvm", 2000, 1.0, 0.1, status="OOM"),
    ]
    out = bench.add_ratios(rows)
    ours, fast, sk = out[0], out[1], out[2]
    assert ours["time_ratio"] == pytest.approx(0.5 / 0.2)
    assert ours["rmse_ratio"] == pytest.approx(0.110 / 0.105)
    assert ours["rmse_f_ratio"] == pytest.approx(0.050 / 0.040)
    assert (ours["best_peer_time"], ours["best_peer_rmse"]) == ("fastrvm", "sklearn-rvm")
    assert fast["time_ratio"] == pytest.approx(1.0)
    assert sk["rmse_ratio"] == pytest.approx(1.0)
    assert out[3]["time_ratio"] is None  # the failed row itself has no ratio
    assert out[4]["time_ratio"] is None and out[4]["rmse_ratio"] is None  # no peer finished
    assert rows[0].get("time_ratio") is None  # inputs are not modified


def test_check_targets_verdicts():
    t = bench.Targets(fit_seconds={5000: 3.0}, peak_mb={20000: 4096.0}, rmse_ratio=1.02)
    rows = bench.add_ratios(
        [
            _row("bayes_fdi", 5000, 3.0, 0.102),  # exactly at both limits -> PASS
            _row("fastrvm", 5000, 5.0, 0.100),
            _row("bayes_fdi", 7000, 9.0, 0.1031),  # RMSE 1.031 x best peer -> FAIL
            _row("fastrvm", 7000, 8.0, 0.100),
            _row("bayes_fdi", 20000, 20.0, 0.1, peak=4097.0),  # no peer: RMSE n/a; memory FAIL
        ]
    )
    checks = {(c["n"], c["what"]): c for c in bench.check_targets(rows, t)}
    assert checks[(5000, "fit CPU s")]["verdict"] == "PASS"
    assert checks[(5000, "test RMSE / best peer")]["verdict"] == "PASS"
    assert checks[(5000, "test RMSE / best peer")]["value"] == pytest.approx(1.02)
    assert checks[(7000, "test RMSE / best peer")]["verdict"] == "FAIL"
    assert (7000, "fit CPU s") not in checks  # no time target at 7000 in this Targets
    assert checks[(20000, "peak MB")]["verdict"] == "FAIL"
    assert checks[(20000, "test RMSE / best peer")]["verdict"] == "n/a"
    slow = bench.add_ratios([_row("bayes_fdi", 5000, 3.01, 0.1), _row("fastrvm", 5000, 1, 0.1)])
    assert bench.check_targets(slow, t)[0]["verdict"] == "FAIL"
    crashed = [{"method": "bayes_fdi", "n": 5000, "status": "timeout", "detail": "> 300 CPU s"}]
    verdicts = {c["what"]: c["verdict"] for c in bench.check_targets(bench.add_ratios(crashed), t)}
    assert verdicts == {"fit CPU s": "FAIL", "test RMSE / best peer": "FAIL"}


def test_ratio_targets_against_fastrvm_and_the_floors():
    """Ours / fastrvm and ours / floor, checked as at most the limit; n/a where not measured."""
    t = bench.Targets(
        fit_seconds={},
        peak_mb={},
        rmse_ratio=1.02,
        fastrvm_ratio={2000: 0.5, 5000: 0.5},
        floor_ratio={5000: 2.0},
        streaming_floor_ratio={5000: 2.0},
    )
    rows = bench.add_ratios(
        [
            _row("fastrvm", 2000, 4.0, 0.1),
            _row("bayes_fdi", 2000, 2.0, 0.1),  # 0.5x fastrvm: at the limit
            _row("fastrvm", 5000, 10.0, 0.1),
            {**_row("bayes_fdi", 5000, 6.0, 0.1), "floor_s": 3.0, "floor_streaming_s": 2.0},
        ]
    )
    checks = {(c["n"], c["what"]): c for c in bench.check_targets(rows, t)}
    assert checks[(2000, "time / fastrvm")]["verdict"] == "PASS"
    assert checks[(5000, "time / fastrvm")]["value"] == 0.6
    assert checks[(5000, "time / fastrvm")]["verdict"] == "FAIL"
    assert checks[(5000, "time / float64 floor")]["value"] == 2.0
    assert checks[(5000, "time / float64 floor")]["verdict"] == "PASS"
    assert checks[(5000, "time / streaming floor")]["value"] == 3.0
    assert checks[(5000, "time / streaming floor")]["verdict"] == "FAIL"
    no_floor = bench.add_ratios([_row("bayes_fdi", 5000, 6.0, 0.1)])
    verdicts = {c["what"]: c["verdict"] for c in bench.check_targets(no_floor, t)}
    assert verdicts["time / fastrvm"] == verdicts["time / float64 floor"] == "n/a"


# -------------------------------------------------------------------------------- table
def test_format_table_rows_columns_and_statuses():
    rows = bench.add_ratios(
        [
            _row("fastrvm", 2000, 0.5, 0.105),
            {**_row("bayes_fdi", 2000, 0.25, 0.1071), "floor_s": 0.1, "floor_streaming_s": 0.05},
            {"method": "sklearn-rvm", "n": 2000, "status": "skipped", "detail": "timeout at N=500"},
            _row("bayes_fdi", 500, 0.1, 0.11),
        ]
    )
    lines = bench.format_table(rows).splitlines()
    n_cols = lines[0].count("|")
    assert all(line.count("|") == n_cols for line in lines)
    assert n_cols - 1 == 14
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in lines[2:]]
    # ordered by N, then method order (bayes_fdi, fastrvm, sklearn-rvm, ...)
    assert [(c[0], c[1]) for c in cells] == [
        ("500", "bayes_fdi"),
        ("2000", "bayes_fdi"),
        ("2000", "fastrvm"),
        ("2000", "sklearn-rvm"),
    ]
    ours = cells[1]
    assert ours[2] == "0.25" and ours[6] == "0.1071"
    assert ours[9] == "0.500" and ours[10] == f"{0.1071 / 0.105:.3f}"
    assert ours[11] == "0.500" and ours[12] == "2.50"  # against fastrvm, against the floor
    assert ours[13] == "5.00"  # against the streaming floor
    assert cells[0][9] == "–" and cells[0][11] == "–" and cells[0][12] == "–"  # no peer, floor
    assert cells[0][13] == "–"
    assert cells[3][2] == "skipped (timeout at N=500)"
    report = bench.format_report(rows, {"sigma": 0.5, "gamma": 2.0, "n_test": 10})
    assert "| 2000 | test RMSE / best peer | 1.02 | 1.020 | PASS |" in report


# --------------------------------------------------------------------- skips, repeats
def test_extrapolation_is_exact_for_power_laws_and_skips_follow():
    c = 1e-7
    hist = [_row("fastrvm", n, c * n**2.5, 0.1, peak=50 + 8e-6 * n**2) for n in (500, 2000)]
    assert bench.extrapolate_fit_seconds(hist, 5000, 2.0) == pytest.approx(c * 5000**2.5)
    # one point: the declared exponent is used
    assert bench.extrapolate_fit_seconds(hist[:1], 1000, 3.0) == pytest.approx(c * 500**2.5 * 8)
    assert bench.extrapolate_fit_seconds([], 1000, 3.0) == 0.0
    assert bench.extrapolate_peak_mb(hist, 20000) == pytest.approx(50 + 8e-6 * 20000**2)
    fast = bench.METHODS["fastrvm"]
    kw = {"timeout_s": 300.0, "mem_limit_mb": 12 * 1024.0}
    assert bench.skip_reason(fast, 5000, hist, **kw) is None
    # t(20000) = 1e-7 * 20000^2.5 = 5657 s > 300 s
    assert bench.skip_reason(fast, 20000, hist, **kw).startswith("est. 5657 s")
    big = [_row("fastrvm", 5000, 1.0, 0.1, peak=2050.0, base=50.0)]  # 2000 MB * 16 + 50
    assert "GB guard" in bench.skip_reason(fast, 20000, big, **kw)
    failed = [{"method": "fastrvm", "n": 2000, "status": "timeout"}]
    assert bench.skip_reason(fast, 5000, failed, **kw) == "timeout at N=2000"
    ours = bench.METHODS["bayes_fdi"]
    assert bench.skip_reason(ours, 5000, [{**failed[0], "method": "bayes_fdi"}], **kw) is None


def test_summarise_repeats_keeps_fastest_cpu_and_largest_peak():
    runs = [_row("fastrvm", 500, t, 0.1, peak=p) for t, p in ((0.3, 120.0), (0.2, 110.0))]
    s = bench.summarise_repeats(runs)
    assert s["fit_cpu_s"] == 0.2 and s["peak_rss_mb"] == 120.0 and s["repeats"] == 2
    with pytest.raises(ValueError, match="disagree"):
        bench.summarise_repeats([runs[0], _row("fastrvm", 500, 0.2, 0.2)])


# ------------------------------------------------------------ worker and guards (subprocess)
def test_run_worker_end_to_end_and_guards(tmp_path):
    from sklearn.linear_model import ARDRegression

    data = bench.make_data(80, 40, seed=2)
    path = tmp_path / "d.npz"
    np.savez(path, **data)
    res = bench.run_worker(
        sys.executable, "sklearn-ard", path, 80, 0.5, timeout_s=120.0, mem_limit_mb=8192.0
    )
    assert res["status"] == "ok", res
    # independent in-process fit of the same model gives the same test RMSE
    K = bench.rbf_kernel_sigma(data["X_train"], data["X_train"], 0.5)
    ref = ARDRegression(fit_intercept=True).fit(K, data["y_train"])
    pred = ref.predict(bench.rbf_kernel_sigma(data["X_test"], data["X_train"], 0.5))
    assert res["rmse"] == pytest.approx(math.sqrt(np.mean((pred - data["y_test"]) ** 2)), 1e-8)
    assert res["n_rv"] == np.count_nonzero(ref.coef_)
    assert res["peak_rss_mb"] >= res["rss_before_fit_mb"] > 0
    assert res["threads"] == 1  # OMP/OpenBLAS pools limited to one thread
    oom = bench.run_worker(
        sys.executable, "sklearn-ard", path, 80, 0.5, timeout_s=120.0, mem_limit_mb=1.0
    )
    assert oom["status"] == "OOM"
    slow = bench.run_worker(
        sys.executable, "sklearn-ard", path, 80, 0.5, timeout_s=0.01, mem_limit_mb=8192.0
    )
    assert slow["status"] == "timeout"
    bad = bench.run_worker(
        sys.executable, "sklearn-ard", path, 10_000, 0.5, timeout_s=120.0, mem_limit_mb=8192.0
    )
    assert bad["status"] == "error" and "exceeds" in bad["detail"]


def test_replace_marked_block_keeps_surroundings_and_rejects_bad_markers():
    text = f"intro\n{bench.BEGIN_MARK}\nold table\n{bench.END_MARK}\noutro\n"
    new = bench.replace_marked_block(text, "| new |\n")
    assert new == f"intro\n{bench.BEGIN_MARK}\n| new |\n{bench.END_MARK}\noutro\n"
    assert bench.replace_marked_block(new, "| new |") == new  # idempotent
    with pytest.raises(ValueError, match="marker"):
        bench.replace_marked_block("no markers", "x")


def test_render_saved_reproduces_the_report(tmp_path):
    rows = [_row("bayes_fdi", 5000, 2.5, 0.101), _row("fastrvm", 5000, 5.0, 0.1)]
    meta = {"sigma": 0.5, "gamma": 2.0, "n_test": 2000, "command": "python x.py", "total_s": 9.0}
    path = tmp_path / "r.json"
    path.write_text(bench.json.dumps({"meta": meta, "rows": bench.add_ratios(rows)}))
    assert bench.render_saved(path) == bench.format_report(rows, meta)
    # the smooth problem's target at N = 5000 is 0.5 CPU s (bench.TARGETS)
    assert "| 5000 | fit CPU s | 0.5 | 2.500 | FAIL |" in bench.render_saved(path)
    assert "Command: `python x.py` (total 9 s wall)." in bench.render_saved(path)


def test_floor_counts_the_fits_products_and_iterations_without_changing_it(monkeypatch):
    """benchmarks/rvm_floor.py: one counted decision per iteration, exactly one product for the
    first column and one per addition (additions counted separately, at the carried factors'
    update), the fit itself unchanged, and the solver's functions restored afterwards (counts
    only: no timing asserted)."""
    floor = load_benchmark("rvm_floor")
    import bayes_fdi.rvm.sbl.gaussian as gaussian_module  # the module whose decision is counted
    from bayes_fdi.rvm import RVR
    from bayes_fdi.rvm.sbl import Design, TrackedFactors

    additions = [0]
    add = TrackedFactors.add

    def counted_add(self, *args, **kwargs):
        additions[0] += 1
        return add(self, *args, **kwargs)

    monkeypatch.setattr(TrackedFactors, "add", counted_add)
    rmatmul, decide = Design.rmatmul, gaussian_module.lazy_verified_action
    r = floor.measure("smooth", 300)
    n_add = additions[0]  # the measured fit's (the reference fit below adds its own)
    assert Design.rmatmul is rmatmul and gaussian_module.lazy_verified_action is decide
    data = bench.make_data(300, problem="smooth")
    ref = RVR(kernel="rbf", width=bench.PROBLEMS["smooth"].sigma, method="fast", bias=True)
    ref.fit(data["X_train"], data["y_train"])
    assert r["log_evidence"] == ref.log_evidence_
    assert r["iterations"] == ref.n_iter_ == r["decisions"]
    assert r["relevance_vectors"] == len(ref.relevance_indices_)
    assert n_add >= r["relevance_vectors"] - 1 > 0
    assert r["products"] == 1 + n_add
    assert r["relevance_vectors"] <= r["M_max"] and 1 <= r["mean_M"] <= r["M_max"]
    assert r["product_mb"] == 8 * 300 * 301 / 2 / 1e6  # dsymv reads one float64 triangle
    assert math.isnan(r["target_s"])  # no target at N = 300
