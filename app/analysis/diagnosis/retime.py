"""Frames a buffering logger held and then wrote back-to-back: put them back where they were sampled.

A gateway or a USB interface under load holds frames for tens to hundreds of milliseconds and then
hands them over at once; the log stamps each with its arrival, so a periodic channel shows a hole of
several periods followed by a run of frames a fraction of a millisecond apart. Their values are
right, their times are not: a torque reversal in such a run is placed up to a few hundred
milliseconds late, the simulated impact with it, and one event's residual becomes a hundred times
the noise floor (an independent-generator drive without any effect read 13x the floor from three
such events, ``docs/diagnosis.md``).

:func:`retime_bursts` finds each run (a hole longer than 1.5 periods, then at least two frames
closer than a quarter period) and gives its frames the times a periodic channel would have had,
counted back from the run's last frame (the one written when the buffer was released, the latest
time that is still true) one period apart. When the run holds more frames than the hole has room
for (the periods do not fit between the frame before the hole and the release), the run is left as
it is and counted as unresolved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

HOLE_PERIODS = 1.5
TIGHT_PERIODS = 0.25


@dataclass(frozen=True)
class Retimed:
    """What :func:`retime_bursts` changed on one channel: runs re-timed, frames moved, runs left as they were."""

    bursts: int = 0
    frames: int = 0
    unresolved: int = 0

    def __add__(self, other: Retimed) -> Retimed:
        return Retimed(self.bursts + other.bursts, self.frames + other.frames, self.unresolved + other.unresolved)


def retime_bursts(t: FloatArray, period: float) -> tuple[FloatArray, Retimed]:
    """Timestamps with each buffered run spread back over its hole (see the module docstring).

    Parameters
    ----------
    t : (n,) logged timestamps (s), non-decreasing.
    period : the channel's nominal period (s).
    """
    t = np.asarray(t, dtype=np.float64)
    if t.size < 4 or not period > 0:
        return t, Retimed()
    d = np.diff(t)
    tight = d < TIGHT_PERIODS * period
    holes = np.flatnonzero((d[:-1] > HOLE_PERIODS * period) & tight[1:])  # hole between i and i+1, run after
    if holes.size == 0:
        return t, Retimed()
    out = t.copy()
    done = Retimed()
    for i in holes:
        last = i + 1  # the run is frames i+1 .. last, each closer than a quarter period to the one before
        while last + 1 < t.size and tight[last]:
            last += 1
        k = last - i  # frames in the run
        times = t[last] - period * np.arange(k - 1, -1, -1, dtype=np.float64)
        if times[0] <= t[i] + 0.5 * period:  # more frames than the hole has periods: frames were lost too
            done = done + Retimed(unresolved=1)
            continue
        out[i + 1:last + 1] = times
        done = done + Retimed(bursts=1, frames=int(k) - 1)
    return out, done
