"""Issue 17, items 2, 3 and 8, through the daemon: control belongs to a client.

The demo's drives, simulated, with a real Modbus TCP client per address (several
loopback addresses: 127.0.0.1 is the PLC, 127.0.0.2 the HMI) and real Zenoh
sessions that carry their session id in the source info.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from collections.abc import AsyncIterator
from pathlib import Path

from pymodbus.client import AsyncModbusTcpClient

from gateway.adapter import EventKind
from gateway.model import Source
from tests.e2e.harness import PREFIX, RUN, TIMEOUT, Gateway
from tests.reliability.demo import (
    UNITS,
    Events,
    at_speed,
    demo_gateway,
    now,
    stopped,
)
from tests.reliability.test_safety import plc_run, weg
from tests.support.timing import scaled
from tests.zenoh.client import Client

KEEP_ALIVE = 3  # holding register 3 (docs/modbus-map.md)
PLC = "127.0.0.1"
HMI = "127.0.0.2"


def modbus_port(gw: Gateway) -> int:
    return int(gw.modbus.comm_params.port)


@contextlib.asynccontextmanager
async def modbus_client(gw: Gateway, source: str) -> AsyncIterator[AsyncModbusTcpClient]:
    client = AsyncModbusTcpClient(
        "127.0.0.1",
        port=modbus_port(gw),
        source_address=(source, 0),
        reconnect_delay=0,
        retries=0,
        timeout=TIMEOUT,
    )
    assert await client.connect()
    try:
        yield client
    finally:
        client.close()


async def write(client: AsyncModbusTcpClient, unit: int, address: int, value: int) -> None:
    rr = await client.write_register(address, value, device_id=unit)
    assert not rr.isError(), rr


def zenoh_client(gw: Gateway) -> Client:
    """A second Zenoh session, identified, connected to the gateway's own endpoint."""
    endpoint = gw.daemon.runtime.config.zenoh.listen[0]
    return Client(endpoint, asyncio.get_running_loop(), identified=True)


async def command(client: Client, drive: str, payload: object) -> dict[str, object]:
    reply = await client.aone(f"{PREFIX}/drives/{drive}/command", payload)
    answer: dict[str, object] = reply.json()
    return answer


# ---------------------------------------------------------------- item 2


async def test_another_modbus_clients_keepalive_never_feeds_the_plcs_watchdog(
    tmp_path: Path,
) -> None:
    timeout = scaled(1.5)
    drives = {"cfw700": {"command_timeout": timeout}}
    async with demo_gateway(tmp_path, drives) as gw, modbus_client(gw, HMI) as hmi:
        unit = UNITS["cfw700"]
        with Events(gw) as events:
            await plc_run(gw, "cfw700", 900)
            silent_since = now()  # the PLC goes silent; the HMI keeps writing its keep-alive
            await gw.wait_for("cfw700", at_speed(900.0))
            watchdog = asyncio.create_task(events.text("cfw700", "no command from modbus"))
            count = 0
            while not watchdog.done():
                count += 1
                await write(hmi, unit, KEEP_ALIVE, count)
                await asyncio.sleep(timeout / 8)
            event = await watchdog
            assert event.text == (
                f"no command from modbus {PLC} for {timeout:g} s: ramp_stop applied"
            )
            assert now() - silent_since >= timeout
            assert count >= 4  # the HMI wrote all along
            await gw.wait_for("cfw700", stopped)
            assert weg(gw, "cfw700").running is False


async def test_another_zenoh_sessions_empty_commands_never_feed_the_watchdog(
    tmp_path: Path,
) -> None:
    timeout = scaled(1.5)
    drives = {"cfw320": {"command_timeout": timeout}}
    async with demo_gateway(tmp_path, drives) as gw:
        scada, other = zenoh_client(gw), zenoh_client(gw)
        try:
            with Events(gw) as events:
                assert (await command(scada, "cfw320", {"run": True, "speed_rpm": 900}))["accepted"]
                state = await gw.wait_for("cfw320", at_speed(900.0))
                assert state.control_client == scada.label
                watchdog = asyncio.create_task(events.text("cfw320", "no command from zenoh"))
                while not watchdog.done():
                    assert (await command(other, "cfw320", {}))["accepted"]
                    await asyncio.sleep(timeout / 8)
                event = await watchdog
                assert f"no command from zenoh {scada.label} for" in event.text
                await gw.wait_for("cfw320", stopped)
        finally:
            scada.close()
            other.close()


async def test_a_session_that_takes_the_published_client_id_is_another_client(
    tmp_path: Path,
) -> None:
    """Issue 32 item 9: a session opened with the id the state published as the controller's
    fed its watchdog, and the drive kept turning after its controller left."""
    timeout = scaled(1.5)
    drives = {"cfw320": {"command_timeout": timeout}}
    async with demo_gateway(tmp_path, drives) as gw:
        scada = zenoh_client(gw)
        try:
            with Events(gw) as events:
                assert (await command(scada, "cfw320", {"run": True, "speed_rpm": 900}))["accepted"]
                state = await gw.wait_for("cfw320", at_speed(900.0))
                published = state.control_client
                assert published is not None and published != scada.zid
                endpoint = gw.daemon.runtime.config.zenoh.listen[0]
                copier = Client(
                    endpoint, asyncio.get_running_loop(), identified=True, zid=published
                )
                try:
                    assert int(copier.zid, 16) == int(published, 16)  # Zenoh took the copied id
                    # (it prints an id without its leading zeros)
                    watchdog = asyncio.create_task(events.text("cfw320", "no command from zenoh"))
                    while not watchdog.done():
                        assert (await command(copier, "cfw320", {}))["accepted"]
                        await asyncio.sleep(timeout / 8)
                    event = await watchdog
                    assert f"no command from zenoh {scada.label} for" in event.text
                    await gw.wait_for("cfw320", stopped)
                finally:
                    copier.close()
        finally:
            scada.close()


async def test_a_command_from_another_modbus_client_takes_control_and_stops(
    tmp_path: Path,
) -> None:
    async with demo_gateway(tmp_path) as gw, modbus_client(gw, HMI) as hmi:
        unit = UNITS["cfw700"]
        with Events(gw) as events:
            await plc_run(gw, "cfw700", 900)
            await gw.wait_for("cfw700", at_speed(900.0))
            await write(hmi, unit, 1, 600)  # the HMI writes only the speed register
            await events.text("cfw700", f"control passed from modbus {PLC} to modbus {HMI}")
            state = await gw.wait_for("cfw700", stopped)
            assert state.control_source is Source.MODBUS and state.control_client == HMI
            # the PLC, still writing its run bit at 1, is no edge: nothing restarts
            await gw.write(unit, 0, RUN)
            assert not gw.daemon.hub.desired("cfw700").run


# ---------------------------------------------------------------- item 3


async def _flood_client(port: int, source: str, units: list[int]) -> None:
    """One client at ``source``: writes command word 0 to every unit, then leaves."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))
    try:
        frames = b"".join(
            struct.pack(">HHHBBHH", tid, 0, 6, unit, 6, 0, 0) for tid, unit in enumerate(units)
        )
        writer.write(frames)
        for _ in units:  # a reply each (an echo, or an exception for a drive not online)
            header = await reader.readexactly(7)
            await reader.readexactly(struct.unpack(">H", header[4:6])[0] - 1)
    finally:
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()


async def test_writes_from_many_addresses_never_lose_a_connected_plcs_run_edge(
    tmp_path: Path,
) -> None:
    async with demo_gateway(tmp_path) as gw:
        unit = UNITS["cfw700"]
        port = modbus_port(gw)
        units = sorted(UNITS.values())
        await gw.write(unit, 1, 900)
        await gw.write(unit, 0, 0)  # the PLC's word: stopped (remembered)
        sources = [f"127.1.{i // 200}.{i % 200 + 1}" for i in range(1100)]
        for start in range(0, len(sources), 50):  # 1,100 other clients, 50 at a time
            batch = sources[start : start + 50]
            await asyncio.gather(*(_flood_client(port, s, units) for s in batch))
        # (the flood may have kept the loop from the line long enough to drop a slave)
        await gw.wait_for("cfw700", lambda s: s.online)
        await gw.write(unit, 1, 900)  # the PLC takes control back with its speed
        await gw.write(unit, 0, RUN)  # and its run edge is obeyed
        assert gw.daemon.hub.desired("cfw700").run
        await gw.wait_for("cfw700", at_speed(900.0))


# ---------------------------------------------------------------- item 8


async def test_every_accepted_command_is_in_the_audit_trail(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        scada = zenoh_client(gw)
        try:
            with gw.client.subscribe(f"{PREFIX}/drives/cfw320/events") as inbox:
                await asyncio.sleep(0)
                assert (await command(scada, "cfw320", {"run": True, "speed_rpm": 600}))["accepted"]
                got = await inbox.auntil(lambda g: g.json()["kind"] == "command", TIMEOUT)
            body = got.json()
            assert body["kind"] == EventKind.COMMAND.value
            assert body["source"] == "zenoh" and body["client"] == scada.label
            assert body["changes"] == {"run": True, "speed_rpm": 600.0}
            assert body["text"] == (
                f"command from zenoh {scada.label} accepted: run False -> True, "
                "speed_rpm None -> 600.0"
            )
        finally:
            scada.close()
