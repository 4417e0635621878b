"""app.progress: one ``progress(fraction, stage)`` contract, and parts of a run mapped onto their share."""

from __future__ import annotations

from app.progress import no_progress, within


def test_a_part_reports_on_its_share_of_the_whole() -> None:
    seen: list[tuple[float, str]] = []
    decode = within(lambda f, s: seen.append((f, s)), 0.0, 0.4)
    analyse = within(lambda f, s: seen.append((f, s)), 0.4, 0.6)
    decode(0.5, "decode")
    analyse(0.0, "events")
    analyse(1.0, "done")
    assert seen == [(0.2, "decode"), (0.4, "events"), (1.0, "done")]


def test_a_part_may_report_under_one_stage_name() -> None:
    seen: list[tuple[float, str]] = []
    reader = within(lambda f, s: seen.append((f, s)), 0.0, 1.0, "decode")
    reader(0.25, "4096 frames read")
    assert seen == [(0.25, "decode")]
    assert no_progress(0.5, "anything") is None
