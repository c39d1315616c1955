"""Checks the WEG manuals ask for, through the Profibus adapter against the simulators
over a pty pair (issue 20): P741 of the CFW320 read at connect, record 48 reads asking for
240 bytes, the CFW320 fire-mode and CFW-11 PID-automatic bits in the published state."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from adapters.profibus.weg.sim.drive import WegSim
from gateway.adapter import EventKind
from gateway.model import CommState
from tests.profibus.support import line_config, running_line

pytestmark = pytest.mark.filterwarnings("error")


def weg(line: Any, address: int) -> WegSim:
    device = line.sim[address].device
    assert isinstance(device, WegSim)
    return device


async def test_cfw320_set_to_profidrive_is_refused_with_an_event_and_never_online() -> None:
    config = line_config([5], drive={"device": "CFW320"})
    async with running_line(config) as line:
        sub = line.hub.subscribe_events()
        weg(line, 5).values[741] = 0  # PROFIdrive at the HMI, before the master connects
        async with asyncio.timeout(10):
            while True:
                event = await sub.get()
                if event.kind is EventKind.CONFIG:
                    break
        assert "P741 = 0 (profidrive)" in event.text
        assert "data_profile is manufacturer (P741 = 1)" in event.text
        assert line.hub.state("d5").comm is not CommState.ONLINE
        assert not line.adapter.diagnostics()["drives"]["d5"]["configured"]
        # set back to the manufacturer's profile at the HMI: the next attempt succeeds
        weg(line, 5).values[741] = 1
        await line.online("d5", limit=15.0)


async def test_record_48_reads_ask_for_240_bytes() -> None:
    config = line_config([5], drive={"device": "CFW320", "param_record": 48})
    async with running_line(config) as line:
        await line.online("d5", limit=10.0)
        sim = weg(line, 5)
        sim.values[100] = 85
        assert await line.hub.read_param("d5", 100) == 85
        assert sim.record_read_lengths[-1] == (48, 240)  # CFW320 5.2.3 "Size 240"


@pytest.mark.parametrize(
    ("device", "knob", "key"),
    [("CFW320", "fire_mode", "fire_mode"), ("CFW-11", "pid_automatic", "pid_automatic")],
)
async def test_fire_mode_and_pid_automatic_reach_the_state(
    device: str, knob: str, key: str
) -> None:
    async with running_line(line_config([5], drive={"device": device})) as line:
        await line.online("d5", limit=10.0)
        await line.until("d5", lambda s: s.values.get(key) == 0)
        setattr(weg(line, 5), knob, True)
        await line.until("d5", lambda s: s.values.get(key) == 1)
