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
