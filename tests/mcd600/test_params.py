"""Parameter mode: reads and writes through the programming structure (guide 4.4)."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from adapters.mcd600.layout import Mode
from adapters.mcd600.paramtable import (
    COMMAND_SOURCE,
    CURRENT_LIMIT,
    MODEL_FLC,
    START_RAMP_TIME,
    STOP_TIME,
    CommandSource,
)
from adapters.mcd600.programming import ParamRequest
from gateway.errors import DriveOffline, GatewayTimeout, ParameterError
from gateway.model import DesiredCommand
from tests.mcd600.loop import Loop, running_bus


class NoChannel:
    async def read_record(self, slot: int, index: int, length: int) -> bytes:
        raise AssertionError("the MCD 600 has no DP-V1")

    async def write_record(self, slot: int, index: int, data: bytes) -> None:
        raise AssertionError("the MCD 600 has no DP-V1")


CH = NoChannel()


def param_loop(**options: Any) -> Loop:
    return Loop(Mode.PARAMETER, **options)


async def test_read_and_write() -> None:
    loop = param_loop()
    async with running_bus(loop):
        assert await loop.profile.read_param(CH, COMMAND_SOURCE, 0) == CommandSource.NETWORK
        await loop.profile.write_param(CH, START_RAMP_TIME, 0, 3)
        assert loop.sim.params[START_RAMP_TIME] == 3
        assert await loop.profile.read_param(CH, START_RAMP_TIME, 0) == 3
        assert await loop.profile.read_param(CH, START_RAMP_TIME, 0) == 3  # same number again
        await loop.profile.write_param(CH, START_RAMP_TIME, 0, 4.0)  # integral float is fine
        assert await loop.profile.read_param(CH, START_RAMP_TIME, 0) == 4
    # between requests the programming outputs are idle
    assert loop.profile.outputs(DesiredCommand(), loop.now)[3:] == bytes(4)


async def test_the_request_on_the_wire() -> None:
    loop = param_loop()
    loop.step()
    async with running_bus(loop):
        await loop.profile.write_param(CH, CURRENT_LIMIT, 0, 400)
    loop.step()
    requests = [ParamRequest.decode(out[3:]) for out in loop.sent]
    distinct = [r for i, r in enumerate(requests) if i == 0 or r != requests[i - 1]]
    # idle, the write (4.4.1 table 7: number 6, byte 4 bit 2, value 0x0190), idle again
    assert distinct == [
        ParamRequest(),
        ParamRequest(CURRENT_LIMIT, write=True, value=400),
        ParamRequest(),
    ]
    assert bytes.fromhex("06 04 01 90") in [out[3:] for out in loop.sent]


async def test_invalid_number() -> None:
    loop = param_loop()
    async with running_bus(loop):
        with pytest.raises(ParameterError) as info:
            await loop.profile.read_param(CH, 200, 0)
        assert info.value.code == 1
        assert info.value.text == "parameter 200: invalid parameter number"
        # the channel works on after a refusal
        assert await loop.profile.read_param(CH, CURRENT_LIMIT, 0) == 350


async def test_invalid_value() -> None:
    loop = param_loop()
    async with running_bus(loop):
        with pytest.raises(ParameterError) as info:
            await loop.profile.write_param(CH, CURRENT_LIMIT, 0, 700)
        assert (info.value.code, info.value.text) == (2, "parameter 6: invalid parameter value")
        with pytest.raises(ParameterError, match="invalid parameter value"):
            await loop.profile.write_param(CH, MODEL_FLC, 0, 10)  # read only
    assert loop.sim.params[CURRENT_LIMIT] == 350


async def test_concurrent_requests_are_served_one_at_a_time() -> None:
    loop = param_loop()
    async with running_bus(loop):
        values = await asyncio.gather(
            loop.profile.read_param(CH, CURRENT_LIMIT, 0),
            loop.profile.read_param(CH, STOP_TIME, 0),
            loop.profile.read_param(CH, COMMAND_SOURCE, 0),
        )
    assert list(values) == [350, 5, 1]


async def test_no_answer_is_a_timeout() -> None:
    loop = param_loop(param_timeout=0.02)
    loop.step()
    with pytest.raises(GatewayTimeout, match="parameter 6"):
        await loop.profile.read_param(CH, CURRENT_LIMIT, 0)  # nobody cycles the bus
    loop.step(3)
    assert loop.profile.outputs(DesiredCommand(), loop.now)[3:] == bytes(4)


async def test_comm_lost_ends_a_pending_request() -> None:
    loop = param_loop()
    loop.step()
    task = asyncio.create_task(loop.profile.read_param(CH, CURRENT_LIMIT, 0))
    await asyncio.sleep(0)
    loop.profile.on_comm_lost()
    with pytest.raises(DriveOffline):
        await task


async def test_reading_the_changed_parameter_clears_it() -> None:
    loop = param_loop()
    loop.step()
    loop.sim.keypad_change(STOP_TIME, 9)
    [event] = loop.diag()
    assert event.data == {"number": STOP_TIME}
    async with running_bus(loop):
        assert await loop.profile.read_param(CH, STOP_TIME, 0) == 9
    assert loop.sim.ext_diag() == b""  # 5.1.2: reset when the master reads it
    loop.sim.keypad_change(STOP_TIME, 8)  # the same parameter changes again: reported again
    [again] = loop.diag()
    assert again.data == {"number": STOP_TIME}


async def test_parameters_in_extended_mode_are_refused() -> None:
    loop = Loop(Mode.EXTENDED)
    with pytest.raises(ParameterError, match='needs mode = "parameter"'):
        await loop.profile.read_param(CH, 1, 0)
