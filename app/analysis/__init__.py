"""Analysis: tip-in/tip-out events, ripple metrics, alignment and comparison.

Pure functions on :mod:`app.signals` objects and numpy arrays with typed, frozen
results; no file or network I/O happens here.
"""
