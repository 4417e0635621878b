"""The model form a log chooses: how a contact's damper engages (:attr:`sim.params.Vehicle.contact_damping`).

The default contact law is Modelica's elasto-backlash: the damping torque is limited to the spring torque, so
the torque is continuous at contact and never pulls. On a stiff, lightly damped driveline (the paper's car) that
limit hardly acts. On a soft, heavily damped compliance behind a lash -- a formula-student car whose tyre and chassis
compliance sit in its half-shafts, damping ratio near 0.5 -- it removes most of the damping while the penetration
is small, i.e. at every impact after the lash closes: the first overshoot then swings 10-20 % further than a damper
acting in full (``full``). Which law a car follows is a property of the car, so the log decides it.

Where the vehicle has a contact with both a clearance and damping, the identification under the file's law leaves
more than :data:`FORM_MIN_GAP` times the noise floor, and the other law, at the identified values, moves that residual
by more than :data:`FORM_SKIP` (two simulator passes, :func:`law_change`), the identification is run again under the
other law on the same events, weights and nuisance baseline (:func:`app.identify.fit.identify_events`); the other law
is kept where it leaves at most :data:`FORM_SHARE` of the file law's residual. (The two-inertia model has one lumped
lash and no contact law: there the two laws are the same model and the second run is skipped.) The law is model
form, not a base parameter: it is reported and written into the identified vehicle, never *named* as a data-sheet
error.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from app.analysis.diagnosis.forward import DiagEvent
from app.analysis.diagnosis.partners import residual_at
from app.identify.base import BASE_EFFECTS
from sim import Vehicle
from sim.params import CONTACT_LAWS

if TYPE_CHECKING:
    from app.identify.fit import Identification

FORM_SHARE = 0.9  # the other law must leave at most this share of the file law's identified residual ...
FORM_MIN_GAP = 1.5  # ... where the file's law leaves more than this many times the noise floor
# ... and where, at the identified values, the other law moves that residual by more than this share: below it the
# two laws are the same model for this car (the paper car's drives: 0.2-5 %; the low-mode chain car's: 126-1080 %)
FORM_SKIP = 0.1


def alternative(vehicle: Vehicle) -> Vehicle | None:
    """``vehicle`` under the other contact law, or None where the law cannot matter (no contact has both a clearance
    and damping)."""
    m = vehicle.compiled
    if not np.any((m.chalf > 0.0) & (m.cc > 0.0)):
        return None
    other = CONTACT_LAWS[1] if vehicle.contact_damping == CONTACT_LAWS[0] else CONTACT_LAWS[0]
    return vehicle.with_changes({"contact_damping": other})


def law_change(first: Identification, other: Vehicle, events: Sequence[DiagEvent], model: str) -> float:
    """How far the other law moves the identified vehicle's residual (relative), at the identified values and, where
    the lash was fitted away from the file's, also with the lash at the file's value (the larger): two or four
    simulator passes, against a whole identification under the other law (inf where the simulator rejects one).

    Why the second point: under the wrong law the lash takes up the law's signature. A smaller lash shortens the
    free traverse and softens the impact the way a damper acting in full does, so at the identified lash the two laws
    can look alike (a low-mode chain car with dampers in full, identified under the limited law: lash 0.43x its true
    value, and the other law moving the residual by 0.8 % there), while at the file's lash they differ many times
    over (docs/identify.md, "The contact law and the lash")."""
    assert first.on is not None
    fit = first.fit
    lash = BASE_EFFECTS["lash"]
    at_file = tuple((eff, lash.off_values()) if eff.id == lash.id else (eff, vals) for eff, vals in fit.settings)
    points = [fit.settings] if at_file == tuple(fit.settings) else [fit.settings, at_file]
    change = 0.0
    for settings in points:
        ra = residual_at(first.on, events, fit.nuisance, settings, model)
        rb = residual_at(other, events, fit.nuisance, settings, model)
        if ra is None or rb is None:
            return float("inf")
        a = float(ra @ ra)
        change = max(change, abs(float(rb @ rb) - a) / max(a, 1e-300))
    return change


def residual(ident: Identification) -> float:
    """The identified vehicle's calibration residual, in units of the noise floor."""
    return ident.chi2_after / max(ident.n_samples, 1)


def choose(first: Identification, second: Identification | None, change: float | None = None) -> Identification:
    """``first`` (the file's law) or ``second`` (the other; None where it was not tried -- the file's law leaves no
    more than :data:`FORM_MIN_GAP`, or the other law moves it by less than :data:`FORM_SKIP` (``change``) -- or could
    not be identified), with the choice recorded on the one returned."""
    a = residual(first)
    b = residual(second) if second is not None else float("nan")
    take = second is not None and a > FORM_MIN_GAP and b <= FORM_SHARE * a
    chosen = second if take and second is not None else first
    file_law = first.on.contact_damping if first.on is not None else CONTACT_LAWS[0]
    law = chosen.on.contact_damping if chosen.on is not None else file_law
    chosen.form = {"contact_damping": law, "file": file_law, "changed": law != file_law,
                   "residual_to_noise": {file_law: round(a, 4)} | (
                       {second.on.contact_damping: round(b, 4)} if second is not None and second.on is not None
                       else {})}
    if a <= FORM_MIN_GAP:
        why = f"the file's law leaves {a:.3g} times the noise floor, nothing to choose on"
    elif second is None and change is not None and change <= FORM_SKIP:
        why = (f"at the identified values the other law moves the residual by {100 * change:.1f} %, under "
               f"{100 * FORM_SKIP:g} %: the same model for this car")
    elif second is None:
        why = "the other contact law could not be identified"
    elif take:
        why = f"its residual is {b / a:.2f}x the file's law's ({b:.3g} against {a:.3g} times the noise floor)"
    else:
        why = f"the other law leaves {b / a:.2f}x its residual, not below {FORM_SHARE:g}x"
    chosen.fit_log.append(f"contact damping: {law}{' (the file says ' + file_law + ')' if take else ''}: {why}")
    return chosen
