"""What a diagnosed state means in words (bayes_fdi.diagnosis.seva.names)."""

from __future__ import annotations

import pytest

from bayes_fdi.actuator import FAULT_TABLE
from bayes_fdi.diagnosis.seva import STATUS_MEANINGS, SevaStatus, describe_state


@pytest.mark.parametrize("code", sorted(FAULT_TABLE))
def test_every_fault_code_is_named_by_its_table_entry(code):
    assert describe_state(code) == f"{code} {FAULT_TABLE[code].description}"


def test_groups_measurement_faults_and_answers_that_are_not_faults():
    assert describe_state("f18") == "f18 fully or partly opened bypass valve"
    assert describe_state("f4|f11") == (
        "f4|f11: f4 increase of valve or bushing friction, or f11 servomotor spring fault"
    )
    assert describe_state("bias_X") == "bias_X bias of the stem position reading alone"
    assert describe_state("drift_F") == "drift_F drift of the flow reading alone"
    assert describe_state("fn") == "fn: no fault detected"
    assert describe_state("mismatch").startswith("mismatch: model mismatch")
    assert "unlike every fault" in describe_state("unknown")
    assert "detection only" in describe_state("unknown", detection_only=True)
    assert describe_state("something-else") == "something-else"


def test_every_status_has_a_meaning():
    assert set(STATUS_MEANINGS) == {s.value for s in SevaStatus}
