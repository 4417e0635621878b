"""The one progress contract: ``progress(fraction, stage)``.

Every long-running function of the service takes a :class:`Progress` and calls it with the share of its
work done (0..1) and a short stage name (``"decode"``, ``"simulate"``, ``"tolerance"``; a reader says how
many frames it has read). Nothing below the front doors prints: the job kinds hand a
:func:`app.jobkinds.progress_reporter` that writes the job row (what ``GET /analyses/{id}`` shows), the
command line a printer on stderr. A part of a larger run reports through :func:`within`, which maps its
0..1 onto its share of the whole.

The simulator (``sim``, which imports nothing from ``app``) reports counts instead,
``progress(done, total)`` of :func:`sim.batch.tolerance_analysis`; the service turns them into a fraction
where it calls it (:mod:`app.analysis.tolerance`).
"""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    def __call__(self, fraction: float, stage: str, /) -> None: ...


def no_progress(fraction: float, stage: str, /) -> None:
    """A :class:`Progress` that reports nowhere (the default everywhere)."""


def within(progress: Progress, start: float, span: float, stage: str | None = None) -> Progress:
    """``progress`` for a part that covers ``start .. start + span`` of the whole; its 0..1 is mapped there.
    With ``stage`` every report carries that stage name instead of the part's own."""
    def report(fraction: float, name: str, /) -> None:
        progress(start + span * fraction, stage if stage is not None else name)

    return report


ETA_MIN_FRACTION = 0.05  # below this share done, a straight-line estimate of the time left means nothing
ETA_MIN_ELAPSED_S = 2.0  # ... nor after less than this long


def eta_seconds(fraction: float, elapsed_s: float) -> float | None:
    """Seconds left at the pace so far (``elapsed * (1 - f) / f``), or None while too little is done to say.

    A straight line through the work done: the stages of a diagnosis or an identification are not equally
    long, so the figure is a guide that firms up as the run goes on (the command line and the REST job
    status show it as "about ... left").
    """
    if not (ETA_MIN_FRACTION <= fraction < 1.0) or not elapsed_s >= ETA_MIN_ELAPSED_S:
        return None
    return float(elapsed_s * (1.0 - fraction) / fraction)


def eta_text(fraction: float, elapsed_s: float) -> str:
    """``", about 40 s left"`` (minutes from 120 s on), or "" while :func:`eta_seconds` has no figure."""
    eta = eta_seconds(fraction, elapsed_s)
    if eta is None:
        return ""
    return f", about {eta:.0f} s left" if eta < 120.0 else f", about {eta / 60.0:.0f} min left"
