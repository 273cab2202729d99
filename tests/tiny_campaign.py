"""The small five-state campaign shared by the reproduce end-to-end and determinism tests."""

# Five states of the paper whose faults move the flow residual strongly in the DAMADICS
# model (f1: valve clogging, f17: pressure change, f18: bypass open; see the reference's
# effect table), plus fn and f2.
#: States of the tiny campaign.
STATES = ["fn", "f1", "f2", "f17", "f18"]
#: Its TOML (``.format(states=...)``).
CAMPAIGN = """
[campaign]
name = "tiny"
seed = 5
duration = 100
source = "benchmark-inputs"
runs_per_state = 24
states = {states}
batch_size = 60

[inputs]
vary = true

[faults]
strength = [0.5, 1.0]
onset = 0.0
profile = "abrupt"
ramp = 0.0
"""
