"""Page's two-sided CUSUM written out by hand: the reference the compiled detectors' tests
compare with."""

from __future__ import annotations

import math

import numpy as np


def hand_two_sided_sums(e, k, cap):
    """``(S+, S-)`` per sample of Page's two-sided recursion with reference ``k``, capped at
    ``cap``; a NaN sample counts as an innovation of 0 (the sums decay by ``k``)."""
    sp = sn = 0.0
    out = []
    for v in e:
        x = 0.0 if math.isnan(v) else v
        sp = min(cap, max(0.0, sp + x - k))
        sn = min(cap, max(0.0, sn - x - k))
        out.append((sp, sn))
    return np.array(out).reshape(-1, 2)
