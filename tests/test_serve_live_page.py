"""The live page of ``serve``: the fast end to end run (the simulated plant at 4x real time with an
f1 fault on V1 -> ``serve`` -> Debian's chromium shows V1's f1 alarm and none for the healthy V2),
and the page's history after a restart: `LiveHub.load` of the log's last records before the new
ones gives the history and alarms of the same records added one by one, and `read_recent` gives
the log's last seconds as `read_log` does."""

from __future__ import annotations

import shutil

import numpy as np
from serve_helpers import Process, fit_tiny_model, free_ports, write_toml

from bayes_fdi.datasets.units import PHYSICAL_UNITS
from bayes_fdi.deployment.serve.durable_log import DurableLog, read_log, read_recent
from bayes_fdi.deployment.serve.live_page import LiveHub

T0 = 1_800_057_000  # plant time of the first record (600 s before a UTC midnight)


def _rows(n, seed, dd_spans):
    """``n`` records of one valve (row dicts of the log's columns), DD on in ``dd_spans``."""
    rng = np.random.default_rng(seed)
    dd = np.zeros(n, dtype=bool)
    for a, b in dd_spans:
        dd[a:b] = True
    rows = []
    for i in range(n):
        blind = i % 97 == 50
        nan = float("nan")
        row = {
            "time": T0 + i,
            **{c: float(rng.uniform(0.2, 0.8)) for c in ("CV", "P1", "P2", "T1", "X", "F")},
            "VMV_X": nan if blind else float(rng.uniform(0.2, 0.8)),
            "VU_X": nan if blind else 0.01,
            "VMV_F": nan if blind else float(rng.uniform(0.2, 0.8)),
            "VU_F": nan if blind else 0.02,
            "status": "BLIND" if blind else ("BLURRED" if dd[i] else "CLEAR"),
            "state": "f1" if dd[i] else "fn",
            "probability": 0.9 if dd[i] else nan,
            "DD": bool(dd[i]),
        }
        rows.append(row)
    return rows


def _hub():
    return LiveHub({"V1": dict(PHYSICAL_UNITS), "V2": dict(PHYSICAL_UNITS)}, 300, 2)


def test_history_loaded_before_new_records_equals_the_records_added_in_order():
    rows = {"V1": _rows(700, 1, [(100, 130), (380, 420), (690, 700)]), "V2": _rows(700, 2, [])}
    whole = _hub()
    for i in range(700):
        for v in ("V1", "V2"):
            whole.add(v, rows[v][i])
    restarted = _hub()
    for i in range(400, 700):  # the new process's records: V1 is inside an alarm at 400
        for v in ("V1", "V2"):
            restarted.add(v, rows[v][i])
    for v in ("V1", "V2"):  # then the log's last records before them (some overlap)
        old = rows[v][:410]
        columns = {k: np.array([r[k] for r in old]) for k in old[0]}
        restarted.load(v, columns)
    a, b = whole.snapshot(), restarted.snapshot()
    assert a["history"] == b["history"] and a["latest"] == b["latest"]
    assert len(a["history"]["V1"]["t"]) == 300  # the last history_seconds only
    assert b["alarms"] == a["alarms"]  # replayed from the loaded records, newest first
    starts = [(x["start"] // 1000 - T0, x["end"], x["active"]) for x in b["alarms"]]
    assert starts == [
        (690, None, True),
        (380, (T0 + 420) * 1000, False),
        (100, (T0 + 130) * 1000, False),
    ]


def test_recent_seconds_of_the_log_are_those_read_log_gives(tmp_path):
    log = DurableLog(tmp_path, {"V1": ("f1",)}, segment_seconds=50)
    rows = _rows(1000, 3, [(10, 20)])  # across midnight: a daily file and segments
    for r in rows:
        r |= {"FFID": not r["DD"], "group_proba": np.array([0.5])}
        r |= {k: 0.0 for k in ("r_X", "r_F", "stat_X", "stat_F", "novelty")}
        r |= {"reason": "", "note": "", "received": 0.0, "published": 0.0}
    for i in range(0, 1000, 10):
        log.commit({"V1": rows[i : i + 10]}, {})
    log.flush()
    assert (tmp_path / "V1" / "V1_2027-01-15.nc").exists()
    whole = read_log(tmp_path, "V1")
    for seconds in (1, 37, 500, 700, 5000):
        recent = read_recent(tmp_path, "V1", seconds)
        want = whole.isel(time=slice(-min(seconds, 1000), None))
        np.testing.assert_array_equal(recent["time"].values, want["time"].values)
        for name in ("X", "VMV_F", "status", "DD"):
            np.testing.assert_array_equal(recent[name].values, want[name].values)
    assert read_recent(tmp_path, "V9", 10) is None


def test_the_page_shows_the_alarm_of_a_fault_injected_in_the_simulated_plant(tmp_path):
    """Fast, in the default run: about 30 s (a small model, 60 plant seconds at 4x)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service as ChromeService
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    model = fit_tiny_model(tmp_path / "tiny.npz")
    plant_port, seva_port, http_port = free_ports(3)
    valves = {"V1": 'fault = {name = "f1", strength = 0.7, onset = 20}', "V2": ""}
    toml = write_toml(
        tmp_path / "valve.toml",
        plant_port=plant_port,
        seva_port=seva_port,
        valves=valves,
        speed=4.0,
        simulation="duration = 60",
    )
    serve = Process(
        ["serve", "--config", str(toml), "--model", str(model), "--http", str(http_port)], tmp_path
    )
    plant = Process(["simulate-plant", "--config", str(toml), "--wait-subscribed"], tmp_path)
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run"):
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path / 'chromium'}")
    driver = None
    try:
        serve.wait_for("serve: 2 valve(s)", 60)
        plant.wait_for("simulated plant:", 60)
        driver = webdriver.Chrome(
            options=options, service=ChromeService(shutil.which("chromedriver"))
        )
        driver.get(f"http://127.0.0.1:{http_port}/")
        wait = WebDriverWait(driver, 45, poll_frequency=0.2)
        wait.until(lambda d: "f1" in d.find_element(By.ID, "alarms").text)
        rows = [r.text for r in driver.find_elements(By.CSS_SELECTOR, "#alarms tbody tr")]
        assert len(rows) == 1 and "V1" in rows[0] and "f1" in rows[0] and "%" in rows[0], rows
        assert driver.find_elements(By.CSS_SELECTOR, "#X-V1 .main-svg")  # plotly drew it
    finally:
        if driver is not None:
            driver.quit()
        serve.stop()
        plant.stop()
