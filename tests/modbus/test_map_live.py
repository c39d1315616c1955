"""The fixed map against a running gateway: status block, signed speeds, FC3 mirror, nulls."""

from __future__ import annotations

from gateway.modbus.map import MIRROR_OFFSET
from gateway.modbus.regs import to_signed16
from gateway.model import DriveStatus
from tests.modbus.conftest import D1, D2, INPUTS, StartGateway

ONLINE, READY, RUNNING, REVERSE, AT_REF, FAULTED, ALARM, REMOTE = (1 << b for b in range(8))


async def test_status_block_of_a_stopped_drive(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    client = await gw.client()
    regs = await gw.inputs_until(client, D1, lambda r: r[0] & ONLINE != 0)
    assert regs[0] == ONLINE | READY | REMOTE  # input register 0: flags
    assert regs[1] == DriveStatus.READY.value == 1  # input register 1: status code
    assert regs[2] == 0  # speed rpm
    assert regs[3] == 0  # speed 0.01 %
    assert regs[13] == 2  # comm online
    assert regs[15] == 0  # control "any"
    assert regs[16] == 0  # no command watchdog
    assert (regs[17] << 16 | regs[18]) == gw.hub.state("d1").seq
    assert regs[19] == 255  # device code: test
    assert regs[20] == 3  # bus address


async def test_nulls_use_the_documented_sentinels(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    client = await gw.client()
    regs = await gw.inputs_until(client, D2, lambda r: r[0] & ONLINE != 0)
    # a soft starter has no speed: int16 null 0x8000, not 0
    assert regs[2] == regs[3] == regs[4] == regs[5] == 0x8000
    assert regs[9] == 0x8000  # power: not given (int16)
    assert regs[10] == 0xFFFF  # voltage: not given (uint16)
    assert regs[11] == 0xFFFF  # no fault code
    assert regs[19] == 5  # MCD 600


async def test_fc3_mirror_equals_the_input_block(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    client = await gw.client()
    await gw.inputs_until(client, D1, lambda r: r[0] & ONLINE != 0)
    state = gw.hub.state("d1")
    fc4 = await client.read_input_registers(0, count=INPUTS, device_id=D1)
    fc3 = await client.read_holding_registers(MIRROR_OFFSET, count=INPUTS, device_id=D1)
    assert gw.hub.state("d1").seq == state.seq  # nothing changed in between
    assert fc3.registers == fc4.registers
    one = await client.read_holding_registers(MIRROR_OFFSET + 2, count=2, device_id=D1)
    assert one.registers == fc4.registers[2:4]


async def test_run_reverse_stop_follow_in_the_registers(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    client = await gw.client()
    for address, value in ((0, 0), (1, 900), (0, 0x0001)):
        assert not (await client.write_register(address, value, device_id=D1)).isError()
    regs = await gw.inputs_until(client, D1, lambda r: r[0] & AT_REF != 0 and r[2] == 900)
    assert regs[0] & (RUNNING | REVERSE) == RUNNING
    assert regs[1] == DriveStatus.RUNNING.value
    assert regs[3] == 5000  # 900 of 1800 rpm = 50.00 %
    assert regs[14] == 2  # control source: modbus
    hold = await client.read_holding_registers(0, count=4, device_id=D1)
    assert hold.registers[:3] == [0x0001, 900, 5000]  # the hub's desired command

    assert not (await client.write_register(0, 0x0003, device_id=D1)).isError()  # reverse
    # at reference: the ramp is over (the rpm register rounds to -900 a little before the
    # speed is there, while the 0.01 % register still shows -49.97 %)
    regs = await gw.inputs_until(
        client, D1, lambda r: r[0] & AT_REF != 0 and to_signed16(r[2]) == -900
    )
    assert regs[2] == 0x10000 - 900  # two's complement
    assert to_signed16(regs[3]) == -5000
    assert regs[0] & REVERSE

    assert not (await client.write_register(0, 0x0000, device_id=D1)).isError()  # stop
    regs = await gw.inputs_until(client, D1, lambda r: r[0] & RUNNING == 0 and r[2] == 0)
    assert regs[1] == DriveStatus.READY.value


async def test_speed_in_percent_and_readback_in_both_units(start_gateway: StartGateway) -> None:
    gw = await start_gateway()
    client = await gw.client()
    rr = await client.write_registers(0, [0x0000, 0x8000, 2500], device_id=D1)
    assert not rr.isError()
    assert gw.hub.desired("d1").speed_pct == 25.0
    hold = await client.read_holding_registers(1, count=2, device_id=D1)
    assert hold.registers == [450, 2500]  # 25 % of 1800 rpm
    assert not (await client.write_register(0, 0x0001, device_id=D1)).isError()
    regs = await gw.inputs_until(client, D1, lambda r: r[0] & AT_REF != 0)
    assert regs[2] == 450


async def test_gateway_unit_reports_health(start_gateway: StartGateway) -> None:
    gw = await start_gateway(gateway_unit=200)
    client = await gw.client()
    for unit in (0, 200):
        rr = await client.read_input_registers(0, count=25, device_id=unit)
        assert not rr.isError(), rr
        regs = rr.registers
        assert regs[0:3] == [0, 1, 0]  # version 0.1.0
        assert regs[5] == 4  # drives configured
        assert regs[6] == 4  # online
        assert regs[7] == 3  # on Modbus (d3 has no unit)
        assert regs[8] == 0  # not read only
        assert regs[9] == 1  # this connection
        mirror = await client.read_holding_registers(MIRROR_OFFSET + 5, count=3, device_id=unit)
        assert mirror.registers == regs[5:8]
    rr = await client.write_register(MIRROR_OFFSET, 1, device_id=0)
    assert rr.isError() and rr.exception_code == 2
