"""Parameters the data do not separate: trade-offs from the Jacobian, the identified combination."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.diagnosis.calibrate import FitResult, trade_offs
from app.analysis.diagnosis.decide import Decision
from app.analysis.diagnosis.forward import Nuisance
from app.analysis.diagnosis.identify import with_identifiability
from app.identify.base import lash_mrad
from sim.effects import apply_effects
from tests.diagnosis.conftest import paper

NAMES = ["gain", "grade_pct", "reducer_scale", "halfshaft_scale"]
OWNERS = ["nuisance", "nuisance", "backlash", "backlash"]


def _jac(mix: float) -> np.ndarray:
    """Residual sensitivities: the two lash columns are ``a`` and ``-(mix a + (1 - mix) b)``."""
    rng = np.random.default_rng(0)
    g, q, a, b = rng.normal(size=(4, 400))
    return np.column_stack([g, q, a, -(mix * a + (1 - mix) * b)])


def test_collinear_columns_are_a_trade_off_with_their_correlation() -> None:
    pairs = trade_offs(_jac(0.99), NAMES, OWNERS)
    assert len(pairs) == 1
    a, b, r = pairs[0]
    assert (a, b) == ("backlash.reducer_scale", "backlash.halfshaft_scale")
    assert r == pytest.approx(0.99, abs=0.01)  # the covariance correlation of two collinear sensitivities


def test_independent_columns_and_nuisance_pairs_are_not_reported() -> None:
    assert trade_offs(_jac(0.2), NAMES, OWNERS) == ()
    j = _jac(0.2)
    j[:, 1] = j[:, 2] + 0.01 * j[:, 1]  # road load standing in for the reducer lash: not an effect pair
    assert all("nuisance" not in a and "nuisance" not in b for a, b, _ in trade_offs(j, NAMES, OWNERS))



def test_a_parameter_the_data_do_not_move_has_no_correlation_and_none_exceeds_one() -> None:
    """A zero column (a second lash the fitted total already sets) has no variance in the pseudo-inverse: its
    correlations are not reported (they read 1e130 from rounding), and no correlation leaves [-1, 1]."""
    j = _jac(0.2)
    j[:, 3] = 1e-300 * j[:, 2]
    assert trade_offs(j, NAMES, OWNERS) == ()
    j[:, 3] = 2.0 * j[:, 2]  # exactly collinear: rounding read 1.0000000000000002
    pairs = trade_offs(j, NAMES, OWNERS)
    assert len(pairs) == 1 and abs(pairs[0][2]) <= 1.0

def test_motor_side_lash_of_the_paper_vehicle() -> None:
    v = paper()
    nominal = lash_mrad(v)
    assert nominal == pytest.approx(373.07, abs=0.01)
    both = apply_effects(v, {"backlash": {"reducer_scale": 2.0, "halfshaft_scale": 2.0}})
    assert lash_mrad(both) == pytest.approx(2 * nominal, rel=1e-9)
    # the half-shaft gap carries 270.4 of the 373.1 mrad: doubling it adds that much
    hs = apply_effects(v, {"backlash": {"reducer_scale": 1.0, "halfshaft_scale": 2.0}})
    assert lash_mrad(hs) - nominal == pytest.approx(270.36, abs=0.01)


def test_decision_names_the_pair_and_the_total_lash() -> None:
    vals = {"backlash": {"reducer_scale": 1.6, "halfshaft_scale": 1.5}}
    fit = FitResult(("backlash",), Nuisance(), vals, 100.0, 100, 10,
                    trade_offs=(("backlash.reducer_scale", "backlash.halfshaft_scale", -0.96),))
    d = with_identifiability(Decision("explained", top=("backlash",), reason="backlash fits"), {"backlash": fit},
                             paper())
    item = d.details["identifiability"][0]
    assert item["params"] == ["backlash.reducer_scale", "backlash.halfshaft_scale"] and item["correlation"] == -0.96
    total = lash_mrad(apply_effects(paper(), vals))
    assert item["identified"]["value"] == pytest.approx(total, abs=1e-3) and item["identified"]["unit"] == "mrad"
    assert "only the total motor-side lash is identified" in d.reason and d.status == "explained"
    # nothing to say without a trade-off, or without an attributed effect
    plain = FitResult(("backlash",), Nuisance(), vals, 100.0, 100, 10)
    d0 = Decision("explained", top=("backlash",), reason="r")
    assert with_identifiability(d0, {"backlash": plain}, paper()) is d0
    none = Decision("no_significant_gap", reason="r")
    assert with_identifiability(none, {"backlash": fit}, paper()) is none
