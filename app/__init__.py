"""lashscope service: ingest CAN logs, analyse tip-in/tip-out events, compare with simulation.

Data flows one way (see docs/architecture.md)::

    log file / upload / live bus
          |  app.ingest      frames -> decoded, named signals
          v
    app.signals            time-correct series (Signal)
          |  app.analysis    events, ripple metrics, alignment, diagnosis
          v
    sim (pure library)     torque -> simulated speed
          |  app.pipeline    chains the stages, reports progress
          v
    app.api / app.cli      REST and command line
"""

__version__ = "0.1.0"
