"""Issue 18: the reason of every exception 3 is logged at debug, with the field and the limit."""

from __future__ import annotations

import logging

import pytest

from tests.modbus.conftest import D1, StartGateway


@pytest.mark.parametrize(
    ("address", "value", "text"),
    [
        (
            1,
            30000,
            "holding register 1 (speed_rpm): speed 30000 rpm is beyond the drive's scale (limit ±",
        ),
        (0, 0x0400, "command word 0x0400 sets reserved bits (0x0400)"),
    ],
)
async def test_exception_3_is_logged_with_field_and_limit(
    start_gateway: StartGateway,
    caplog: pytest.LogCaptureFixture,
    address: int,
    value: int,
    text: str,
) -> None:
    caplog.set_level(logging.DEBUG, "gateway.modbus.frontend")
    gw = await start_gateway()
    plc = await gw.client()
    rr = await plc.write_register(address, value, device_id=D1)
    assert rr.isError() and rr.exception_code == 3
    assert any(text in r.getMessage() for r in caplog.records if r.levelno == logging.DEBUG)
