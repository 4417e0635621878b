"""Time-correct signals: samples + timestamps + unit, with explicit interpolation modes."""

from app.signals.signal import Interp, Signal, SignalSet

__all__ = ["Interp", "Signal", "SignalSet"]
