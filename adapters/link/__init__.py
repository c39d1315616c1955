"""The bus I/O every bus adapter shares: one link per medium and one driver loop per medium.

* :mod:`.engine`: the :class:`~.engine.Engine` protocol every protocol engine follows
  (``step(now, event) -> actions``, ``next_deadline()``), stepped with an injected clock.
* :mod:`.serial`: a serial port on the event loop (pyserial, non-blocking, held exclusively,
  RS-485 direction control), opened through a :class:`~.serial.SerialLinks` factory: the
  real port, or a simulated line the composition root chooses.
* :mod:`.stream`: the driver loop of a byte-stream engine on a serial link (bytes -> the
  protocol's stream codec -> ``step``; transmits written when due); :mod:`.timer`: the
  precise timer its waits are slept on (a timerfd the loop watches).
* :mod:`.can`: a python-can bus on the event loop (read by the loop itself, ``add_reader``,
  when it has a file descriptor; by python-can's ``Notifier(loop=...)`` thread otherwise),
  opened through a :class:`~.can.CanLinks` factory; :mod:`.canerror` decodes SocketCAN error
  frames.
* :mod:`.candriver`: the driver loop of a frame engine on a CAN link; :mod:`.canline`: what
  the CAN adapters' lines share (link events as the engine's, send failures, the bounded
  leave loop).

Nothing here knows a fieldbus protocol: the bus adapters bring their codecs, engines and
events, and this package never imports them (tests/test_layering.py).
"""
