"""Unit conversions, one definition each, for the simulator and the service (``app`` imports them from here:
``sim`` is the bottom layer).

The functions keep the order of operations the project has always used (``x * 30 / pi``, not
``x * (30 / pi)``), so a conversion moved here gives the same bits as the expression it replaces.
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np
import numpy.typing as npt

RPM_PER_RAD_S = 30.0 / math.pi  # 1 rad/s in rpm (60 / 2 pi)
RAD_S_PER_RPM = math.pi / 30.0  # 1 rpm in rad/s

Speed = TypeVar("Speed", float, npt.NDArray[np.float64])


def rad_s_to_rpm(value: Speed) -> Speed:
    """Angular speed (or acceleration, per second) from rad/s to rpm."""
    return value * 30.0 / math.pi


def rpm_to_rad_s(value: Speed) -> Speed:
    """Angular speed (or angle per rpm-second) from rpm to rad/s."""
    return value * math.pi / 30.0
