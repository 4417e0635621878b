"""Independent driveline + CAN generator: validation data the diagnosis' own simulator did not make.

Nothing here imports ``sim`` or ``app`` (tests/bench/test_indep_generator.py parses the imports).
The nominal car is read as data from ``sim/presets/paper.toml`` (so it is the same physical car as
lashscope's ``paper`` preset); the equations, the integrator, the contact law, the tyre, the speed
sensor, the drives and the CAN recording are this package's own:

``car``       physical parameters (paper preset as data) and the truth knobs of every effect
``dynamics``  equations of motion (open differential, two half-shafts, housing, tyres), RK4 in numba
``drive``     torque drives with clusters of reversals and anti-jerk ramps, speed and pedal bands
``record``    speed sensor, CAN frames (quantisation, SNA, jitter, drops, bursts, offset) -> BLF
``cases``     benchmark cases (effects drawn at random, faint ones scaled to a signal size), manifest
"""
