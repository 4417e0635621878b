"""Fleet scale: many logs analysed on Dask (:mod:`app.fleet.batch`), one Parquet row per event
(:mod:`app.fleet.store`), and the per-vehicle lash and ripple report (:mod:`app.fleet.report`).

Nothing here is imported by the service or the CLI until a fleet command (or the event-store hook,
:mod:`app.fleet.hook`) runs; Dask is an optional dependency (``pip install 'lashscope[fleet]'``).
"""
