"""``lashscope ratings fit``: scores matched to analysed events (analysis JSON or event store), typed errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.analysis.ratings import FEATURES
from app.cli import main
from app.fleet.rows import event_rows
from app.fleet.store import write_rows
from app.ratings_file import load_model


def _doc(log: str, n: int, seed: int) -> tuple[dict[str, object], list[float]]:
    """An analysis document with ``n`` events' measured criteria, and the scores of a known rule."""
    rng = np.random.default_rng(seed)
    metrics, events, scores = [], [], []
    for i in range(n):
        pp, kick, jerk = rng.uniform(0.1, 2.5), rng.uniform(0.05, 1.5), rng.uniform(8, 90)
        crit = dict.fromkeys(FEATURES, 0.0) | {"shuffle_pp_ms2": pp, "kick_ms2": kick, "max_jerk_ms3": jerk,
                                                "clunk_ms2": None, "response_delay_s": 0.1, "vdv_ms175": 1.0}
        metrics.append({"event_index": i, "t_cross_s": 2.0 + 3.0 * i, "measured": {}, "simulated": {},
                        "drivability": {"source": "accelerometer", "measured": crit}})
        events.append({"index": i, "kind": "tip_in", "t_cross_s": 2.0 + 3.0 * i})
        scores.append(float(np.clip(round((9.5 - 1.5 * pp - 0.6 * kick - 0.03 * jerk + rng.normal(0, 0.3)) * 2) / 2,
                                    1, 10)))
    return {"log": f"/data/{log}", "metrics": metrics, "events": events, "summary": {}}, scores


def _write(tmp_path: Path, n: int = 30) -> tuple[Path, Path]:
    doc, scores = _doc("drive_a.blf", n, 0)
    analysis = tmp_path / "drive_a.json"
    analysis.write_text(json.dumps(doc), encoding="utf-8")
    lines = ["log,event_index,score"] + [f"drive_a.blf,{i},{s}" for i, s in enumerate(scores)]
    ratings = tmp_path / "ratings.csv"
    ratings.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return analysis, ratings


def test_fit_from_analysis_documents_writes_a_versioned_model(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    analysis, ratings = _write(tmp_path)
    out = tmp_path / "model.json"
    assert main(["ratings", "fit", str(ratings), "--analysis", str(analysis), "--out", str(out)]) == 0
    model = load_model(out)
    assert model.events == 30 and model.cv_rms < 1.0
    assert "clunk_ms2" not in model.features  # null in every event
    text = capsys.readouterr().out
    assert f"rating model {model.version}: 30 scored events" in text


def test_scores_by_time_and_from_the_event_store(tmp_path: Path) -> None:
    doc, scores = _doc("drive_b.blf", 24, 1)
    rows = event_rows(doc, vehicle="ev", log_hash="ab" * 32, log_name="drive_b.blf", source="batch", driveline="ev")
    write_rows(tmp_path / "events", rows, source="batch", log_hash="ab" * 32)
    lines = ["log,time_s,score"] + [f"abababab,{2.0 + 3.0 * i + 0.2},{s}" for i, s in enumerate(scores)]
    ratings = tmp_path / "r.csv"
    ratings.write_text("\n".join(lines) + "\n", encoding="utf-8")
    out = tmp_path / "m.json"
    assert main(["ratings", "fit", str(ratings), "--store", str(tmp_path / "events"), "--out", str(out)]) == 0
    assert load_model(out).events == 24


@pytest.mark.parametrize(("line", "code", "words"), [
    ("drive_x.blf,3,7", "ratings_unknown_event", "no analysed log 'drive_x.blf'"),
    ("drive_a.blf,99,7", "ratings_unknown_event", "has no event 99"),
    ("drive_a.blf,three,7", "ratings_csv", "must be numbers"),
    ("drive_a.blf,0,7", "ratings_csv", "scored twice"),
])
def test_bad_lines_are_one_line_errors_naming_the_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        line: str, code: str, words: str) -> None:
    analysis, ratings = _write(tmp_path)
    ratings.write_text(ratings.read_text(encoding="utf-8") + line + "\n", encoding="utf-8")
    assert main(["ratings", "fit", str(ratings), "--analysis", str(analysis), "--out", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"lashscope: error [{code}]") and words in err and "line 32" in err
    assert "\n" not in err


def test_too_few_scored_events_and_a_time_without_an_event(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    analysis, _ = _write(tmp_path)
    few = tmp_path / "few.csv"
    few.write_text("log,event_index,score\n" + "".join(f"drive_a.blf,{i},6\n" for i in range(10)), encoding="utf-8")
    assert main(["ratings", "fit", str(few), "--analysis", str(analysis)]) == 2
    assert "[ratings_too_few_events]" in capsys.readouterr().err
    far = tmp_path / "far.csv"
    far.write_text("log,time_s,score\ndrive_a.blf,3.5,6\n", encoding="utf-8")
    assert main(["ratings", "fit", str(far), "--analysis", str(analysis)]) == 2
    assert "has no event at 3.5 s (nearest at 2.00 s)" in capsys.readouterr().err


def test_analyze_refuses_a_missing_model_before_any_work(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(tmp_path / "nothing.blf"), "--vehicle", "paper",
                 "--ratings", str(tmp_path / "none.json")]) == 2
    assert "[ratings_model]" in capsys.readouterr().err
