"""Live CAN: replay logs onto a bus with their original timing, and analyse a live bus.

Everything goes through python-can, so any interface python-can supports works
(``socketcan``, ``pcan``, ``vector``, ``kvaser``, ``virtual`` ...), plus ``tcp_loopback``
(:mod:`app.live.loopback`), a bus shared by processes over loopback TCP for machines
without CAN sockets.

* :mod:`app.live.bus` -- open a bus; :class:`~app.live.bus.BusLink` reconnects with backoff.
* :mod:`app.live.replay` -- :class:`~app.live.replay.Replayer`: absolute-deadline pacing.
* :mod:`app.live.session` -- :class:`~app.live.session.LiveSession`: receive, record, decode, analyse.
* :mod:`app.live.recorder` -- BLF recording that survives an abrupt stop (≤ ~1 s lost).
* :mod:`app.live.analyzer` -- events reported as each completes, equal to the offline analysis.
* :mod:`app.live.stream` -- bounded fan-out to dashboard subscribers (server-sent events).
"""
