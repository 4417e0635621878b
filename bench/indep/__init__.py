"""Independent driveline + CAN generator: validation data the diagnosis' own simulator did not make.

Nothing here imports ``sim`` or ``app`` (tests/bench/test_indep_generator.py parses the imports).
The nominal cars are read as data from ``sim/presets/paper.toml`` and ``chain_drive.toml`` (so they
are the same physical cars as lashscope's presets); the equations, the integrator, the contact law,
the tyre, the speed sensor, the drives and the CAN recording are this package's own:

``car``       physical parameters (paper and chain_drive presets as data), the truth knobs of every effect
              and of a wrong data sheet, and the truths in lashscope's terms (stiffness, lash)
``dynamics``  equations of motion (open differential, two half-shafts, housing, tyres), RK4 in numba,
              and their linearisation (first mode)
``drive``     torque drives with clusters of reversals and anti-jerk ramps, speed and pedal bands
``record``    speed sensor, CAN frames (quantisation, SNA, jitter, drops, bursts, offset) -> BLF
``cases``     benchmark cases (effects drawn at random, faint ones scaled to a signal size; wrong data
              sheets for the identification sets), manifest
"""
