"""Driveline simulator: the reference paper's two-inertia and multibody models.

Pure library: numpy, scipy and numba only; imports nothing from ``app``.
"""
