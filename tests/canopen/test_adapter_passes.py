"""The CANopen adapter's refresh of the wishes (hub -> engine, once per cycle) is made in
the driver pass that steps the engine's cycle: it asks for no wake-up of its own.

Stepped with an injected clock: a driver pass at each wake-up the engine and the adapter
ask for (:mod:`adapters.link.candriver`'s order: ``before_step``, the engine's step when
due, ``after_step``), each pass late by a varying amount as on a loaded machine.
"""

from __future__ import annotations

import itertools

from adapters.can.adapter import AdapterLine as _Line
from adapters.canopen.adapter import CanOpenAdapter
from adapters.canopen.master import Master
from adapters.canopen.plan import listen_time
from gateway.config import parse
from gateway.runtime.daemon import build_hub

SYNC_PERIOD = 0.01
LATE = (0.0005, 0.0001, 0.0003, 0.0)  # s: each pass this late, in turn


def test_the_refresh_rides_on_the_cycle_pass() -> None:
    bus = {
        "adapter": "canopen",
        "interface": "virtual",
        "channel": "passes",
        "bitrate": 500_000,
        "sync_period": SYNC_PERIOD,
        "drives": [{"id": "d1", "device": "CiA 402", "address": 1, "eds": "eds/cia402-drive.eds"}],
    }
    config = parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": bus}}, "t"
    )
    adapter = CanOpenAdapter(config.buses[0])
    engine = Master(adapter.master_config(), adapter.node_configs)
    adapter._hub, adapter.engine = build_hub(config), engine
    line = _Line(adapter)
    refreshes: list[float] = []
    refresh = adapter._refresh

    def counted(now: float) -> None:
        refreshes.append(now)
        refresh(now)

    adapter._refresh = counted  # type: ignore[method-assign]
    now, own_wakes, cycles = 0.0, 0, 0
    late = itertools.cycle(LATE)
    end = 1.0 + listen_time(adapter.options)  # no frame while listening
    while now < end:
        line.before_step(now)
        deadline = engine.next_deadline()
        if deadline is None or now >= deadline:
            before = engine.next_cycle
            engine.step(now)
            cycles += engine.next_cycle != before
        else:
            own_wakes += 1  # a pass for the adapter alone
        line.after_step(now)
        times = [t for t in (engine.next_deadline(), line.wake_at()) if t is not None]
        now = max(now, min(times)) + next(late)
    assert own_wakes == 0
    assert cycles >= 0.9 / SYNC_PERIOD
    # one refresh per cycle, in the pass that steps it (and one in the first pass, listening)
    assert len(refreshes) == cycles + 1
