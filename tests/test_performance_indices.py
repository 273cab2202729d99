"""PICalc's indices on hand-made decision streams; every expected value is worked out by hand.

Unless a test says otherwise the zone is Step I's abrupt one: t_on = 300, t_from = 900,
t_hor = 1500, so the fault-free part holds 600 s, the faulty part 600 s, the zone 1200 s.
"""

import numpy as np
import pytest

from bayes_fdi.scoring import PICALC_KEYS, UNDETERMINED, picalc

T = np.arange(0.0, 1500.0)
ZONE = {"t_on": 300, "t_from": 900, "t_hor": 1500}
ABRUPT = np.where(T >= 900, 0.75, 0.0)  # a big abrupt fault's strength stream


def high(*periods, t=T):
    """A bool stream, high on the half-open periods [a, b)."""
    out = np.zeros(t.size, dtype=bool)
    for a, b in periods:
        out[(t >= a) & (t < b)] = True
    return out


def test_keys_are_the_benchmarks_and_a_silent_stream_is_never_detected():
    silent = np.zeros(T.size, dtype=bool)
    out = picalc(T, silent, silent, np.zeros(T.size), **ZONE, strength=ABRUPT,
                 indicated=np.zeros((T.size, 2), bool), group_sizes=[1, 2])  # fmt: skip
    assert tuple(out) == PICALC_KEYS
    # no rising edge at all: every time, strength and dacc undeterminable; every rate 0
    assert out == {
        "t_dt": -1.0, "r_fd": 0.0, "r_td": 0.0, "fs_d": -1.0,
        "t_it": -1.0, "r_fi": 0.0, "r_ti": 0.0, "r_mi": 0.0, "fs_i": -1.0, "dacc": -1.0,
    }  # fmt: skip


def test_permanent_detection_and_isolation():
    dd = high((905, 1500))
    pid = high((930, 1500))
    cid = high((905, 930)).astype(float)  # one other group named while isolating
    out = picalc(T, dd, pid, cid, **ZONE, strength=ABRUPT)
    assert out["t_dt"] == 5.0  # 905 - 900
    assert out["r_fd"] == 0.0
    assert out["r_td"] == pytest.approx(595 / 600)  # 1500 - 905 = 595 s of 600
    assert out["fs_d"] == 0.75  # the abrupt strength at 905
    assert out["t_it"] == 30.0  # 930 - 900
    assert out["r_fi"] == 0.0
    assert out["r_ti"] == pytest.approx(570 / 600)  # 1500 - 930
    assert out["r_mi"] == pytest.approx(25 / 1200)  # CID = 1 for 25 s over the 1200-s zone
    assert out["fs_i"] == 0.75
    assert out["dacc"] == UNDETERMINED  # no indicated stream given


def test_dacc_counts_the_faults_of_every_group_named_after_permanent_isolation():
    dd, pid = high((905, 1500)), high((930, 1500))
    indicated = np.zeros((T.size, 2), dtype=bool)  # group 0 (true, 1 fault), group 1 (3 faults)
    indicated[:, 0] = pid
    indicated[:, 1] = high((905, 930))  # before the PID edge at 930: does not count
    cid = indicated[:, 1].astype(int)
    out = picalc(T, dd, pid, cid, **ZONE, indicated=indicated, group_sizes=[1, 3])
    assert out["dacc"] == 1.0  # L = 1 (group 0 alone from 930 on)
    indicated[:, 1] |= high((1000, 1010))  # group 1 named again after 930
    out = picalc(T, dd, pid, cid, **ZONE, indicated=indicated, group_sizes=[1, 3])
    assert out["dacc"] == 0.25  # L = 1 + 3 faults


def test_flickering_detection_is_timed_to_its_last_rising_edge():
    dd = high((950, 960), (1000, 1010), (1100, 1500))
    out = picalc(T, dd, dd, np.zeros(T.size), **ZONE)
    assert out["t_dt"] == 200.0  # last rising edge at 1100
    assert out["r_td"] == pytest.approx(420 / 600)  # 10 + 10 + 400 s high
    assert out["t_it"] == 200.0 and out["r_ti"] == out["r_td"]


def test_a_detection_dropped_before_the_horizon_is_not_permanent():
    dd = high((950, 960), (1000, 1400))  # low for the last 100 s
    out = picalc(T, dd, dd, np.zeros(T.size), **ZONE)
    assert out["t_dt"] == UNDETERMINED and out["t_it"] == UNDETERMINED
    assert out["r_td"] == pytest.approx(410 / 600)  # the rates do not need permanence
    loose = picalc(T, dd, dd, np.zeros(T.size), **ZONE, permanent=False)
    assert loose["t_dt"] == 100.0  # last rising edge at 1000, whatever follows


def test_a_false_alarm_before_the_fault_that_ends():
    dd = high((400, 460), (920, 1500))
    out = picalc(T, dd, np.zeros(T.size, bool), np.zeros(T.size), **ZONE)
    assert out["r_fd"] == pytest.approx(60 / 600)  # 0.1
    assert out["t_dt"] == 20.0  # 920 - 900: the false alarm is not the detection
    assert out["r_td"] == pytest.approx(580 / 600)
    assert out["t_it"] == UNDETERMINED and out["r_fi"] == 0.0


def test_a_false_alarm_before_the_fault_only_is_no_detection():
    dd = high((400, 500))
    for permanent in (True, False):
        out = picalc(T, dd, dd, np.zeros(T.size), **ZONE, permanent=permanent)
        assert out["t_dt"] == UNDETERMINED  # the last high period ends before t_from
        assert out["r_fd"] == pytest.approx(100 / 600)
        assert out["r_fi"] == pytest.approx(100 / 600)
        assert out["r_td"] == 0.0


def test_a_false_alarm_that_persists_through_the_fault_is_credited_at_t_from():
    dd = high((600, 1500))
    out = picalc(T, dd, dd, np.zeros(T.size), **ZONE, strength=ABRUPT)
    assert out["t_dt"] == 0.0  # rising edge at 600 < t_from: credited at 900
    assert out["fs_d"] == 0.75  # strength at t_from
    assert out["r_fd"] == pytest.approx(300 / 600)  # 600 .. 899 high: 0.5
    assert out["r_td"] == 1.0


def test_a_detection_on_before_the_zone_starts_counts_from_t_on():
    dd = high((0, 1500))  # on through the set-up zone and the whole benchmark zone
    out = picalc(T, dd, dd, np.ones(T.size), **ZONE)
    assert out["t_dt"] == 0.0 and out["t_it"] == 0.0
    assert out["r_fd"] == 1.0 and out["r_td"] == 1.0
    assert out["r_mi"] == 1.0  # CID = 1 during all 1200 s of the zone


def test_samples_outside_the_zone_are_ignored():
    t = np.arange(0.0, 1700.0)
    dd = high((100, 200), (1500, 1700), t=t)  # only in the set-up zone and after t_hor
    out = picalc(t, dd, dd, dd.astype(float), **ZONE)
    assert out["t_dt"] == UNDETERMINED and out["r_fd"] == 0.0 and out["r_td"] == 0.0
    assert out["r_mi"] == 0.0
    zone_only = np.arange(300.0, 1500.0)  # a stream holding just the zone is enough
    out = picalc(zone_only, high((905, 1500), t=zone_only), high((905, 1500), t=zone_only),
                 np.zeros(zone_only.size), **ZONE)  # fmt: skip
    assert out["t_dt"] == 5.0


def test_nan_gaps_count_as_low_and_break_a_detection():
    dd = high((905, 1500)).astype(float)
    dd[(T >= 1000) & (T < 1005)] = np.nan  # 5 BLIND seconds inside the detection
    cid = np.where(np.isnan(dd), np.nan, 0.0)
    out = picalc(T, dd, dd, cid, **ZONE)
    assert out["t_dt"] == 105.0  # the detection restarts at 1005
    assert out["r_td"] == pytest.approx(590 / 600)  # 595 s high minus the 5-s gap
    assert out["r_mi"] == 0.0  # NaN CID counts 0


def test_incipient_strength_at_the_last_edges():
    # f13 incipient: a ramp from 0 at 900 s to 1.0 at 1800 s (t_fd = 900 s), t_hor = 2400 s
    t = np.arange(0.0, 2400.0)
    ramp = np.clip((t - 900.0) / 900.0, 0.0, 1.0)
    dd = high((1000, 1010), (1350, 2400), t=t)
    pid = high((1620, 2400), t=t)
    out = picalc(t, dd, pid, np.zeros(t.size), t_on=300, t_from=900, t_hor=2400, strength=ramp)
    assert out["t_dt"] == 450.0 and out["fs_d"] == pytest.approx(0.5)  # (1350 - 900) / 900
    assert out["t_it"] == 720.0 and out["fs_i"] == pytest.approx(0.8)  # (1620 - 900) / 900
    assert out["r_td"] == pytest.approx((10 + 1050) / 1500)
    no_strength = picalc(t, dd, pid, np.zeros(t.size), t_on=300, t_from=900, t_hor=2400)
    assert no_strength["fs_d"] == UNDETERMINED and no_strength["fs_i"] == UNDETERMINED


def test_worked_example_of_the_benchmark_definition():
    """[BD] App. IV, f13 incipient: t_dt 250 s, r_fd 33 %, r_td 80 %, f_sd 0.45, t_it 500 s,
    r_fi 25 %, r_ti 45 %, r_mi 5 %, f_si 0.8, dacc 0.5.

    The example is not self-consistent with permanence to the end of the zone: a DD edge at
    900 + 250 = 1150 s kept to t_hor = 2400 s gives r_td >= 1250 / 1500 = 83 %, and a PID edge
    at 1400 s kept to the end gives r_ti >= 1000 / 1500 = 67 %, not 45 %. It is rebuilt with the
    literal last-edge reading (``permanent=False``). Its strengths are not rebuildable: no
    linear ramp from t_from gives both 0.45 at 250 s and 0.8 at 500 s (slopes 1.8e-3 vs
    1.6e-3 per s), so fs is checked against f13's own ramp (t_fd = 900 s).
    """
    t = np.arange(0.0, 2400.0)
    zone = {"t_on": 300, "t_from": 900, "t_hor": 2400}
    dd = high((300, 500), (1000, 1050), (1150, 2300), t=t)  # 200 s before; 50 + 1150 s after
    pid = high((350, 500), (1400, 2075), t=t)  # 150 s before the fault, 675 s after
    other = high((1150, 1255), t=t)  # one other group named for 105 s
    indicated = np.stack([pid, other], axis=1)  # the true group holds 2 faults
    ramp = np.clip((t - 900.0) / 900.0, 0.0, 1.0)
    out = picalc(t, dd, pid, other.astype(int), **zone, strength=ramp, indicated=indicated,
                 group_sizes=[2, 1], permanent=False)  # fmt: skip
    assert out["t_dt"] == 250.0  # last DD edge 1150 - 900
    assert round(out["r_fd"], 2) == 0.33  # 200 / 600
    assert out["r_td"] == pytest.approx(0.80)  # (50 + 1150) / 1500
    assert out["t_it"] == 500.0  # last PID edge 1400 - 900
    assert out["r_fi"] == pytest.approx(0.25)  # 150 / 600
    assert out["r_ti"] == pytest.approx(0.45)  # 675 / 1500
    assert out["r_mi"] == pytest.approx(0.05)  # 105 / (2400 - 300)
    assert out["dacc"] == 0.5  # from 1400 on only the true 2-fault group is named
    assert out["fs_d"] == pytest.approx(250 / 900) and out["fs_i"] == pytest.approx(500 / 900)
    strict = picalc(t, dd, pid, other.astype(int), **zone)
    assert strict["t_dt"] == UNDETERMINED  # DD is low over [2300, 2400): not permanent


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"t_on": 900, "t_from": 900, "t_hor": 1500}, "t_on < t_from < t_hor"),
        ({"t_on": 300, "t_from": 900, "t_hor": 1600}, "does not cover the benchmark zone"),
        ({"t_on": 300, "t_from": 900.5, "t_hor": 1500}, "whole number of seconds"),
        ({"t_on": True, "t_from": 900, "t_hor": 1500}, "t_on must be a real number"),
    ],
)
def test_bad_zones_are_named(kwargs, message):
    z = np.zeros(T.size, bool)
    with pytest.raises(ValueError, match=message):
        picalc(T, z, z, np.zeros(T.size), **kwargs)


def test_bad_streams_are_named():
    z = np.zeros(T.size, bool)
    with pytest.raises(ValueError, match="dd must hold 0/1"):
        picalc(T, np.full(T.size, 2.0), z, np.zeros(T.size), **ZONE)
    with pytest.raises(ValueError, match="pid must be 1-D"):
        picalc(T, z, z[:10], np.zeros(T.size), **ZONE)
    with pytest.raises(ValueError, match="cid must hold whole numbers"):
        picalc(T, z, z, np.full(T.size, 0.5), **ZONE)
    with pytest.raises(ValueError, match="steps of 1 s"):
        picalc(T * 2, z, z, np.zeros(T.size), **ZONE)
    with pytest.raises(ValueError, match="strength must be"):
        picalc(T, z, z, np.zeros(T.size), **ZONE, strength=np.full(T.size, np.nan))
    with pytest.raises(ValueError, match="both indicated and group_sizes"):
        picalc(T, z, z, np.zeros(T.size), **ZONE, indicated=np.zeros((T.size, 1), bool))
    with pytest.raises(ValueError, match="group_sizes >= 1"):
        picalc(T, z, z, np.zeros(T.size), **ZONE, indicated=np.zeros((T.size, 1), bool),
               group_sizes=[0])  # fmt: skip
