"""Each line keeps its timing while the daemon's loop is held up (docs/decisions/0071).

The demo's three simulated lines run in the daemon; the test then holds the daemon's own
loop (the hub, Zenoh, Modbus, the page) still for longer than every line's watchdog: the
Profibus DP watchdog, the DeviceNet connections' inactivity (4 x EPR) and the CiA 402
drives' consumer heartbeat. Each line runs on a loop of its own, so no slave leaves data
exchange, no drive goes offline or faults, and the slaves kept exchanging meanwhile.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

from gateway.adapter import EventKind
from tests.reliability.demo import CANOPEN, DEVICENET, PROFIBUS, WEG, demo_gateway, slave
from tests.support.timing import scaled

HOLD = 3.0  # s the daemon's loop stands still: over the demo's 2 s DP watchdog, 4 x EPR
# of the test's DeviceNet timings and the CiA 402 drives' consumer heartbeat


async def test_a_held_up_daemon_loop_stops_no_line(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        counters = {d: slave(gw, d).counters for d in (*WEG, "mcd600")}
        before = {d: (c.exchanges, c.comm_lost) for d, c in counters.items()}
        with gw.daemon.hub.subscribe_events() as events:
            time.sleep(HOLD)  # noqa: ASYNC251 - the daemon's loop held up, on purpose
            during = {d: c.exchanges - before[d][0] for d, c in counters.items()}
            async with asyncio.timeout(scaled(10.0)):  # what the lines said meanwhile
                for bus in (PROFIBUS, DEVICENET, CANOPEN):
                    port = gw.line(bus).port
                    assert port is not None
                    while port.waiting:  # noqa: ASYNC110 - applied on this loop's next pass
                        await asyncio.sleep(0.01)
            seen = [e for e in events.drain() if e.kind in (EventKind.COMM, EventKind.FAULT)]
        assert seen == [], f"a line lost a drive while the daemon's loop stood: {seen}"
        assert all(n > 0 for n in during.values()), f"exchanges during the hold: {during}"
        lost = {d: c.comm_lost - before[d][1] for d, c in counters.items()}
        assert not any(lost.values()), f"slaves that left data exchange: {lost}"
        assert all(s.online and not s.faulted for s in gw.daemon.hub.states())
