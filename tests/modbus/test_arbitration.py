"""Modbus writes under each ``control`` setting of a drive."""

from __future__ import annotations

import pytest

from gateway.errors import CommandRejected
from gateway.model import DriveCommand, Source
from tests.modbus.conftest import D1, StartGateway

DEVICE_FAILURE = 4
ZENOH_RUN = DriveCommand(run=True, speed_rpm=600.0)


async def test_control_any_last_writer_wins_but_rewrites_do_not_steal(
    start_gateway: StartGateway,
) -> None:
    gw = await start_gateway(control="any")
    c = await gw.client()
    assert not (await c.write_register(0, 0x0000, device_id=D1)).isError()
    gw.hub.submit("d1", Source.ZENOH, ZENOH_RUN)
    # the PLC rewrites its unchanged word: Zenoh keeps control and the drive keeps running
    for _ in range(3):
        assert not (await c.write_register(0, 0x0000, device_id=D1)).isError()
    assert gw.hub.desired("d1").source is Source.ZENOH
    assert gw.hub.desired("d1").run
    # a real change from Modbus takes control
    assert not (await c.write_register(0, 0x0001, device_id=D1)).isError()
    assert gw.hub.desired("d1").source is Source.MODBUS
    regs = await gw.inputs_until(c, D1, lambda r: r[14] == 2)  # control source: modbus
    assert regs[15] == 0  # control mode: any
    gw.hub.submit("d1", Source.ZENOH, DriveCommand(run=False))
    assert gw.hub.desired("d1").source is Source.ZENOH


async def test_control_zenoh_refuses_modbus_commands(start_gateway: StartGateway) -> None:
    gw = await start_gateway(control="zenoh")
    c = await gw.client()
    assert not (await c.write_register(0, 0x0000, device_id=D1)).isError()  # a stop: taken
    assert gw.hub.desired("d1").source is Source.NONE  # but it takes no control
    for address, value in ((0, 0x0001), (1, 300), (2, 0x8000)):
        rr = await c.write_register(address, value, device_id=D1)
        assert rr.isError() and rr.exception_code == DEVICE_FAILURE, (address, value)
    assert not (await c.write_register(3, 1, device_id=D1)).isError()  # keep-alive only
    gw.hub.submit("d1", Source.ZENOH, ZENOH_RUN)
    # a Modbus stop is never refused (issue 32): the drive stops, control stays with Zenoh
    assert not (await c.write_register(0, 0x0000, device_id=D1)).isError()
    assert not gw.hub.desired("d1").run
    assert gw.hub.desired("d1").source is Source.ZENOH
    regs = await gw.inputs_until(c, D1, lambda r: r[14] == 1)  # control source: zenoh
    assert regs[15] == 1  # control mode: zenoh


async def test_control_modbus_takes_modbus_only(start_gateway: StartGateway) -> None:
    gw = await start_gateway(control="modbus")
    c = await gw.client()
    assert not (await c.write_register(0, 0x0000, device_id=D1)).isError()
    assert not (await c.write_register(0, 0x0001, device_id=D1)).isError()
    assert gw.hub.desired("d1").run
    with pytest.raises(CommandRejected):
        gw.hub.submit("d1", Source.ZENOH, DriveCommand(speed_rpm=100))
    assert gw.hub.desired("d1").run
    gw.hub.submit("d1", Source.ZENOH, DriveCommand(run=False))  # a stop is never refused
    assert not gw.hub.desired("d1").run
    assert gw.hub.desired("d1").source is Source.MODBUS
    regs = await gw.inputs_until(c, D1, lambda r: r[14] == 2)
    assert regs[15] == 2  # control mode: modbus
