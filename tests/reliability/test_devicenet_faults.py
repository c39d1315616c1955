"""DeviceNet faults through the daemon, with the demo's CFW-08 simulated on the line:
the scanner's own CAN controller going bus-off and restarting (simulated through the
link: the error frames SocketCAN delivers, and sends failing meanwhile), and the drive's
controller going bus-off (E34). A node leaving and returning is shown by
``tests/e2e/test_devicenet_e2e.py::test_a_stopped_node_goes_offline_and_comes_back_stopped``.
"""

from __future__ import annotations

import asyncio

import can
import pytest

from gateway.model import CommState
from tests.e2e.harness import PREFIX, TIMEOUT
from tests.reliability.demo import (
    ADDRESSES,
    DEVICENET,
    Events,
    at_speed,
    can_sim,
    demo_gateway,
    devicenet_adapter,
    on_line,
    stopped,
    until,
)

MAC = ADDRESSES["cfw08"]
CAN_ERR_BUSOFF = 0x040  # error class bits of a SocketCAN error frame (fact sheet Part 3)
CAN_ERR_RESTARTED = 0x100


def error_frame(error_class: int) -> can.Message:
    return can.Message(
        arbitration_id=error_class, is_error_frame=True, is_extended_id=False, data=bytes(8)
    )


async def test_scanner_bus_off_and_restart(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernel reports bus-off with an error frame and sends fail ("Network is down")
    until the controller restarts (``ip link ... restart-ms``) and reports "restarted"."""
    async with demo_gateway(tmp_path) as gw:
        hub = gw.daemon.hub
        adapter = devicenet_adapter(gw)
        link = adapter.link
        assert link is not None and link._bus is not None
        kernel = can.Bus(interface="virtual", channel=adapter.options.channel)
        try:
            with Events(gw) as events, gw.client.liveliness(f"{PREFIX}/drives/cfw08") as token:
                await gw.command("cfw08", {"run": True, "speed_rpm": 600})
                await gw.wait_for("cfw08", at_speed(600.0))
                await token.auntil(lambda g: g.put, TIMEOUT)
                sends: list[can.Message] = []

                def network_down(msg: can.Message, timeout: float | None = None) -> None:
                    sends.append(msg)
                    raise can.CanOperationError("Network is down")

                bus = link._bus  # its sends fail, on the line's loop, from now on
                await on_line(gw, DEVICENET, lambda: monkeypatch.setattr(bus, "send", network_down))
                kernel.send(error_frame(CAN_ERR_BUSOFF))
                await events.text("cfw08", "line: bus-off (health bus-off)")
                await events.text("cfw08", "cannot send (Network is down): backing off")
                await gw.wait_for("cfw08", lambda s: s.comm is CommState.OFFLINE)
                await token.auntil(lambda g: not g.put, TIMEOUT)
                # the line's figures as built after the bus-off (every 0.25 s, on its loop)
                await asyncio.wait_for(gw.line(DEVICENET).next_diagnostics(), TIMEOUT)
                health = (await gw.client.aone(f"{PREFIX}/gateway/health")).json()
                line = health["buses"][DEVICENET]
                assert (line["health"], line["bus_conditions"]) == ("bus-off", {"bus-off": 1})
                assert line["last_tx_failure"] == "Network is down" and line["live"] == []
                await until(lambda: len(sends) >= 3)
                await on_line(gw, DEVICENET, monkeypatch.undo)  # the controller restarts
                kernel.send(error_frame(CAN_ERR_RESTARTED))
                await events.text("cfw08", "line: restarted (health ok)")
                await gw.wait_for("cfw08", lambda s: s.online)
                await token.auntil(lambda g: g.put, TIMEOUT)
                # the drive kept turning on its own (P313 = no action); back under the
                # gateway it is stopped, and only a new run command starts it again
                await events.text("cfw08", "run command cleared: drive left online")
                await gw.wait_for("cfw08", stopped)
                assert can_sim(gw).node(MAC).drive.motor.speed == 0.0
                assert not hub.desired("cfw08").run
                assert (await gw.diagnostics(DEVICENET))["health"] == "ok"
                assert gw.daemon.runtime.restarts.get(f"bus {DEVICENET}", 0) == 0
                await gw.command("cfw08", {"run": True})
                await gw.wait_for("cfw08", at_speed(600.0))
        finally:
            kernel.shutdown()


async def test_drive_bus_off_e34_and_automatic_recovery(tmp_path) -> None:
    """The CFW-08's own controller goes bus-off (E34, P070 = 5) and recovers by itself
    (P703 = 1, seed 4.1.7): the drive drops out and comes back stopped."""
    async with demo_gateway(tmp_path, {"cfw08": {"sim_p313": 2}}) as gw:
        runner = can_sim(gw)
        node = runner.node(MAC)

        def p703_automatic_reset() -> None:
            node.drive.params[703] = 1  # automatic bus-off reset

        await on_line(gw, DEVICENET, p703_automatic_reset)
        with Events(gw) as events:
            await gw.command("cfw08", {"run": True, "speed_rpm": 600})
            await gw.wait_for("cfw08", at_speed(600.0))
            bus_off = lambda n, t: n.bus_off(t, recover_after=0.3)  # noqa: E731
            await on_line(gw, DEVICENET, lambda: runner.call(MAC, bus_off))
            await gw.wait_for("cfw08", lambda s: s.comm is CommState.OFFLINE)
            event = await events.text("cfw08", "drive offline: no data")
            assert "P313 = no action (2)" in event.text  # what the drive did meanwhile
            await gw.wait_for("cfw08", lambda s: s.online)
            await events.text("cfw08", "run command cleared: drive left online")
            await gw.wait_for("cfw08", stopped)
            assert not gw.daemon.hub.desired("cfw08").run
            diag = (await gw.diagnostics(DEVICENET))["drives"]["cfw08"]
            assert diag["offline_count"] == 1 and diag["state"] == "online"
