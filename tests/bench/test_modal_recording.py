"""bench/modal_recording.py's loggers: each defect alone on a clean logger, and the case's logger without each."""

from __future__ import annotations

from dataclasses import asdict

from bench.indep.cases import plan, recording
from bench.modal_recording import loggers


def test_each_logger_differs_from_clean_or_full_by_its_defect_alone() -> None:
    case = next(c for c in plan("ifinal13", False) if c.name == "chain_base_damping_ratio_650029")
    full = recording(case)
    out = loggers(full)
    clean = asdict(out["clean"])
    assert out["full"] == full
    assert clean["speed_noise_rpm"] == clean["torque_noise_nm"] == clean["max_offset_s"] == 0.0
    assert clean["bursts_per_min"] == clean["drop_fraction"] == clean["jitter_s"] == 0.0
    assert clean["period_s"] == full.period_s == 0.02  # the chain car at 50 Hz
    for name, rec in out.items():
        if name.startswith("only "):
            moved = {k for k, v in asdict(rec).items() if v != clean[k]}
            assert moved and all(asdict(rec)[k] == asdict(full)[k] for k in moved), name
            back = asdict(out["all but " + name[5:]])
            assert {k for k, v in back.items() if v != asdict(full)[k]} == moved, name
    assert len(out) == 12
