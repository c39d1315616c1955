"""Every exception case: nothing of a refused request is applied."""

from __future__ import annotations

import pytest

from gateway.modbus.health import GATEWAY_INPUTS
from gateway.modbus.map import MIRROR_OFFSET
from gateway.modbus.regs import block_size
from tests.modbus.conftest import D1, D2, D4, INPUTS, StartGateway, mbap, raw_exchange

ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE, DEVICE_FAILURE, TARGET_FAILED = 1, 2, 3, 4, 0x0B


def code_of(rr: object) -> int | None:
    return getattr(rr, "exception_code", None) if rr.isError() else None  # type: ignore[attr-defined]


async def test_reads_of_unmapped_addresses(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    c = await gw.client()
    assert code_of(await c.read_input_registers(INPUTS, count=1, device_id=D1)) == ILLEGAL_ADDRESS
    assert (
        code_of(await c.read_input_registers(0, count=INPUTS + 1, device_id=D1)) == ILLEGAL_ADDRESS
    )
    assert code_of(await c.read_holding_registers(4, count=1, device_id=D1)) == ILLEGAL_ADDRESS
    assert code_of(await c.read_holding_registers(0, count=5, device_id=D1)) == ILLEGAL_ADDRESS
    assert (
        code_of(await c.read_holding_registers(MIRROR_OFFSET - 1, count=2, device_id=D1))
        == ILLEGAL_ADDRESS
    )
    assert (
        code_of(await c.read_holding_registers(MIRROR_OFFSET + INPUTS, count=1, device_id=D1))
        == ILLEGAL_ADDRESS
    )
    assert code_of(await c.read_coils(0, count=1, device_id=D1)) == ILLEGAL_ADDRESS
    assert code_of(await c.read_discrete_inputs(0, count=1, device_id=D1)) == ILLEGAL_ADDRESS
    assert code_of(await c.write_coil(0, True, device_id=D1)) == ILLEGAL_ADDRESS
    beyond = block_size(GATEWAY_INPUTS)  # the gateway unit's first unmapped input register
    assert code_of(await c.read_input_registers(beyond, count=1, device_id=0)) == ILLEGAL_ADDRESS


async def test_writes_to_registers_that_are_not_writable(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    c = await gw.client()
    assert not (await c.write_registers(0, [0x0000, 300], device_id=D1)).isError()
    before = gw.hub.desired("d1")
    assert code_of(await c.write_register(MIRROR_OFFSET, 1, device_id=D1)) == ILLEGAL_ADDRESS
    assert code_of(await c.write_register(4, 1, device_id=D1)) == ILLEGAL_ADDRESS
    # all or nothing: the valid speed in front of the unmapped register is not applied
    assert code_of(await c.write_registers(1, [600, 0x8000, 7, 9], device_id=D1)) == ILLEGAL_ADDRESS
    assert gw.hub.desired("d1") == before
    hold = await c.read_holding_registers(1, count=1, device_id=D1)
    assert hold.registers == [300]
    # function 23: a valid write with an unmapped read range applies nothing
    rr = await c.readwrite_registers(
        read_address=50, read_count=1, write_address=1, values=[600], device_id=D1
    )
    assert code_of(rr) == ILLEGAL_ADDRESS
    assert gw.hub.desired("d1") == before
    rr = await c.readwrite_registers(
        read_address=0, read_count=3, write_address=1, values=[600], device_id=D1
    )
    assert list(rr.registers) == [0, 600, 3333]  # write first, then read


@pytest.mark.parametrize(
    ("address", "values", "why"),
    [
        (0, [0x0040], "reserved command bit"),
        (0, [0x8001], "reserved command bits"),
        (1, [1801], "beyond 1800 rpm"),
        (1, [0x10000 - 1801], "beyond -1800 rpm"),
        (2, [10001], "beyond 100.00 %"),
        (1, [300, 1000], "both speed references"),
        (0, [0x0000, 5000], "valid word, bad speed: nothing applied"),
    ],
)
async def test_out_of_range_values(
    start_gateway: StartGateway, address: int, values: list[int], why: str
) -> None:
    gw = await start_gateway()
    c = await gw.client()
    before = gw.hub.desired("d1")
    if len(values) == 1:
        rr = await c.write_register(address, values[0], device_id=D1)
    else:
        rr = await c.write_registers(address, values, device_id=D1)
    assert code_of(rr) == ILLEGAL_VALUE, why
    assert gw.hub.desired("d1") == before
    # the refused word was not remembered: the client's first word is still unknown
    assert not (await c.write_register(0, 0x0001, device_id=D1)).isError()
    assert not gw.hub.desired("d1").run


async def test_offline_drive_refuses_commands_but_serves_reads(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    c = await gw.client()
    gw.adapter("line2").online = False
    await gw.wait_state("d4", lambda s: not s.online)
    regs = await gw.inputs_until(c, D4, lambda r: r[0] & 1 == 0)
    assert regs[13] == 0  # comm offline
    # a stop is never refused (issue 32): taken, though there is nothing to stop
    assert not (await c.write_register(0, 0x0000, device_id=D4)).isError()
    assert code_of(await c.write_register(1, 100, device_id=D4)) == DEVICE_FAILURE
    assert not (await c.write_register(3, 1, device_id=D4)).isError()  # keep-alive: harmless
    # the word written while offline is remembered: a held run bit does not start
    # the drive when it comes back
    assert code_of(await c.write_register(0, 0x0001, device_id=D4)) == DEVICE_FAILURE
    gw.adapter("line2").online = True
    await gw.wait_state("d4", lambda s: s.online)
    assert not (await c.write_register(0, 0x0001, device_id=D4)).isError()
    assert not gw.hub.desired("d4").run


async def test_commands_the_hub_refuses(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    c = await gw.client()
    assert not (await c.write_register(0, 0x0000, device_id=D2)).isError()
    before = gw.hub.desired("d2")
    assert code_of(await c.write_register(0, 0x0002, device_id=D2)) == DEVICE_FAILURE  # direction
    assert code_of(await c.write_register(1, 100, device_id=D2)) == DEVICE_FAILURE  # no speed
    assert gw.hub.desired("d2") == before
    # run and fault reset as new edges in one word
    assert not (await c.write_register(0, 0x0000, device_id=D1)).isError()
    assert code_of(await c.write_register(0, 0x0005, device_id=D1)) == DEVICE_FAILURE
    assert not gw.hub.desired("d1").run
    health = await c.read_input_registers(18, count=4, device_id=0)
    accepted = health.registers[0] << 16 | health.registers[1]
    refused = health.registers[2] << 16 | health.registers[3]
    assert (accepted, refused) == (2, 3)


async def test_unknown_units_and_functions(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    c = await gw.client()
    assert code_of(await c.read_input_registers(0, count=1, device_id=9)) == TARGET_FAILED
    assert code_of(await c.read_input_registers(0, count=1, device_id=247)) == TARGET_FAILED
    assert code_of(await c.write_register(0, 0, device_id=9)) == TARGET_FAILED
    # diagnostics (08, return query data): not served
    reply = await raw_exchange(gw.port, mbap(D1, b"\x08\x00\x00\x12\x34", tid=7))
    assert reply == mbap(D1, bytes([0x88, ILLEGAL_FUNCTION]), tid=7)
    # a function code pymodbus does not know at all
    reply = await raw_exchange(gw.port, mbap(D1, b"\x55\x00", tid=8))
    assert reply == mbap(D1, bytes([0xD5, ILLEGAL_FUNCTION]), tid=8)
    # an exception response sent as a request
    reply = await raw_exchange(gw.port, mbap(D1, b"\x84\x02", tid=9))
    assert reply == mbap(D1, bytes([0x84, ILLEGAL_FUNCTION]), tid=9)
    # a served function whose PDU is cut short
    reply = await raw_exchange(gw.port, mbap(D1, b"\x04\x00", tid=10))
    assert reply == mbap(D1, bytes([0x84, ILLEGAL_VALUE]), tid=10)
    # an unknown unit is checked first
    reply = await raw_exchange(gw.port, mbap(99, b"\x55", tid=11))
    assert reply == mbap(99, bytes([0xD5, TARGET_FAILED]), tid=11)


async def test_read_only_refuses_every_write(start_gateway: StartGateway) -> None:
    gw = await start_gateway(read_only=True)
    c = await gw.client()
    before = gw.hub.desired("d1")
    for address in range(4):
        assert code_of(await c.write_register(address, 0, device_id=D1)) == ILLEGAL_FUNCTION
    assert (
        code_of(await c.write_registers(0, [0, 100, 0x8000, 1], device_id=D1)) == ILLEGAL_FUNCTION
    )
    assert (
        code_of(await c.mask_write_register(address=0, and_mask=0, or_mask=1, device_id=D1))
        == ILLEGAL_FUNCTION
    )
    assert code_of(await c.write_register(MIRROR_OFFSET, 0, device_id=D1)) == ILLEGAL_ADDRESS
    assert gw.hub.desired("d1") == before
    assert not (await c.read_input_registers(0, count=INPUTS, device_id=D1)).isError()
    assert not (await c.read_holding_registers(0, count=4, device_id=D1)).isError()
    health = await c.read_input_registers(8, count=1, device_id=0)
    assert health.registers == [1]
