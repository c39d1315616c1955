"""Command semantics: edges per client, fault reset, watchdog keep-alive."""

from __future__ import annotations

import asyncio
from dataclasses import replace

from gateway.adapter import EventKind
from gateway.model import StopAction
from tests.modbus.conftest import D1, TIMEOUT, StartGateway

RUNNING, FAULTED = 1 << 2, 1 << 5


async def test_fault_reset_is_an_edge_and_a_held_run_bit_does_not_restart(
    start_gateway: StartGateway,
) -> None:
    gw = await start_gateway()
    client = await gw.client()
    for address, value in ((1, 600), (0, 0x0000), (0, 0x0001)):
        assert not (await client.write_register(address, value, device_id=D1)).isError()
    await gw.inputs_until(client, D1, lambda r: r[0] & RUNNING != 0)

    adapter = gw.adapter("line1")  # on its line's own thread and loop: poked there
    await gw.daemon.runtime.adapters["line1"].call(lambda: adapter.inject_fault("d1", 42))
    regs = await gw.inputs_until(client, D1, lambda r: r[0] & FAULTED != 0)
    assert regs[11] == 42  # fault code
    assert not gw.hub.desired("d1").run  # the hub cleared run on the fault
    hold = await client.read_holding_registers(0, count=1, device_id=D1)
    assert hold.registers == [0x0000]  # reads back the desired command, not the last write

    # the PLC keeps rewriting its word: no new run command
    assert not (await client.write_register(0, 0x0001, device_id=D1)).isError()
    assert not gw.hub.desired("d1").run
    seq = gw.hub.desired("d1").fault_reset_seq
    # fault reset 0 -> 1 with run held at 1: one reset, no run
    assert not (await client.write_register(0, 0x0005, device_id=D1)).isError()
    assert gw.hub.desired("d1").fault_reset_seq == seq + 1
    regs = await gw.inputs_until(client, D1, lambda r: r[0] & FAULTED == 0)
    assert regs[11] == 0xFFFF
    # reset held at 1, run held at 1: neither repeats
    for _ in range(3):
        assert not (await client.write_register(0, 0x0005, device_id=D1)).isError()
    assert gw.hub.desired("d1").fault_reset_seq == seq + 1
    # reset back to 0 is no reset; run still held at 1
    assert not (await client.write_register(0, 0x0001, device_id=D1)).isError()
    assert gw.hub.desired("d1").fault_reset_seq == seq + 1
    assert not gw.hub.desired("d1").run
    await gw.wait_state("d1", lambda s: not s.running and s.speed_rpm == 0)  # comes to rest
    assert not (await client.write_register(0, 0x0001, device_id=D1)).isError()
    assert not gw.hub.desired("d1").run

    # run 0 -> 1: the drive runs again
    assert not (await client.write_register(0, 0x0000, device_id=D1)).isError()
    assert not (await client.write_register(0, 0x0001, device_id=D1)).isError()
    assert gw.hub.desired("d1").run
    await gw.inputs_until(client, D1, lambda r: r[0] & RUNNING != 0)


async def test_first_word_of_a_new_client_never_starts(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    client = await gw.client()
    assert not (await client.write_register(0, 0x0001, device_id=D1)).isError()
    assert not gw.hub.desired("d1").run
    assert not (await client.write_register(0, 0x0000, device_id=D1)).isError()
    assert not (await client.write_register(0, 0x0001, device_id=D1)).isError()
    assert gw.hub.desired("d1").run


async def test_a_reconnecting_client_is_the_same_client(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    first = await gw.client()
    assert not (await first.write_register(0, 0x0000, device_id=D1)).isError()
    assert not (await first.write_register(0, 0x0001, device_id=D1)).isError()
    assert gw.hub.desired("d1").run
    first.close()
    gw.hub.apply_stop("d1", StopAction.RAMP_STOP, "test: link lost")  # as the watchdog would
    second = await gw.client()  # same address, new connection
    assert not (await second.write_register(0, 0x0001, device_id=D1)).isError()
    assert not gw.hub.desired("d1").run


async def test_rewriting_the_same_word_changes_nothing(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    client = await gw.client()
    assert not (await client.write_registers(0, [0x0000, 300], device_id=D1)).isError()
    before = gw.hub.desired("d1")
    events = 0
    with gw.hub.subscribe_events() as sub:
        for _ in range(5):
            assert not (await client.write_registers(0, [0x0000, 300], device_id=D1)).isError()
        events = len(sub.drain())
    assert gw.hub.desired("d1") == before
    assert events == 0


async def test_keepalive_feeds_the_watchdog(start_gateway: StartGateway) -> None:
    gw = await start_gateway(command_timeout=0.3)
    client = await gw.client()
    regs = await gw.inputs_until(client, D1, lambda r: r[16] == 3)  # 0.3 s in 0.1 s
    assert regs[16] == 3
    for address, value in ((1, 300), (0, 0x0000), (0, 0x0001)):
        assert not (await client.write_register(address, value, device_id=D1)).isError()
    with gw.hub.subscribe_events() as sub:
        # a PLC cycle of 50 ms feeding only the keep-alive, for longer than the timeout
        for i in range(12):
            assert not (await client.write_register(3, i, device_id=D1)).isError()
            await asyncio.sleep(0.05)
        assert gw.hub.desired("d1").run
        assert not [e for e in sub.drain() if e.kind is EventKind.SAFETY]
        hold = await client.read_holding_registers(3, count=1, device_id=D1)
        assert hold.registers == [11]  # the keep-alive reads back the last value written

        async def safety() -> None:
            while (await sub.get()).kind is not EventKind.SAFETY:
                pass

        await asyncio.wait_for(safety(), TIMEOUT)  # feeding stopped: the watchdog stops
    assert not gw.hub.desired("d1").run
    assert not (await client.write_register(0, 0x0001, device_id=D1)).isError()
    assert not gw.hub.desired("d1").run  # a held run bit is not a new run command


async def test_a_stop_word_with_a_stop_kind_the_drive_lacks_stops_it(
    start_gateway: StartGateway,
) -> None:
    """Issue 32 item 4: run = 0 with quick stop = 1 to a drive without quick stop (the
    CFW320) was refused whole and remembered, so the PLC's next run = 0 sent nothing."""
    gw = await start_gateway()
    caps = gw.hub.capabilities("d1")
    unsupported = {**caps.unsupported, "quick_stop": "the drive has no quick stop"}
    gw.hub.set_capabilities("d1", replace(caps, unsupported=unsupported))
    client = await gw.client()
    for address, value in ((1, 600), (0, 0x0000), (0, 0x0001)):
        assert not (await client.write_register(address, value, device_id=D1)).isError()
    assert gw.hub.desired("d1").run
    assert not (await client.write_register(0, 0x0008, device_id=D1)).isError()  # run 0, QS 1
    assert not gw.hub.desired("d1").run
    assert not (await client.write_register(0, 0x0000, device_id=D1)).isError()
    assert not gw.hub.desired("d1").run


async def test_a_stop_bit_beside_a_refused_speed_is_applied(start_gateway: StartGateway) -> None:
    """Issue 32 item 4: a write refused for its speed still applies the stop of its word."""
    gw = await start_gateway()
    client = await gw.client()
    for address, value in ((1, 600), (0, 0x0000), (0, 0x0001)):
        assert not (await client.write_register(address, value, device_id=D1)).isError()
    assert gw.hub.desired("d1").run
    reply = await client.write_registers(0, [0x0000, 60000], device_id=D1)  # speed refused
    assert reply.isError()
    assert not gw.hub.desired("d1").run
    assert gw.hub.desired("d1").speed_rpm == 600
