"""End to end over SocketCAN vcan0 between two processes: the daemon here (DeviceNet line
on ``socketcan``/``vcan0``, not simulated) and a simulated CFW-08 started with
``drive-gateway sim devicenet`` in another process. The check the demo gives on
``virtual``: online, run by a Zenoh command, read back over Modbus TCP. Marked ``vcan``
(``make test-vcan``)."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest
import pytest_asyncio

from tests.devicenet.integration.conftest import FAST_BUS, VCAN, sim_process, vcan_problem
from tests.e2e.harness import PREFIX, TIMEOUT, Gateway, parsed, running_gateway

pytestmark = pytest.mark.vcan

UNIT = 5
MAC = 5


def buses() -> str:
    """The line's timers are the rig's, grown with the suite's time scale: in the VM under
    TCG a 50 ms EPR let the connection time out between two slow passes of the loop."""
    timers = "\n".join(f"{key} = {seconds:g}" for key, seconds in FAST_BUS.items())
    return f"""
[buses.dn]
adapter = "devicenet"
interface = "socketcan"
channel = "{VCAN}"
{timers}
[[buses.dn.drives]]
id = "cfw08"
device = "CFW-08"
address = {MAC}
modbus_unit = {UNIT}
assembly = 21
max_rpm = 1800
"""


@pytest_asyncio.fixture
async def gateway(tmp_path: Path) -> AsyncIterator[Gateway]:
    problem = vcan_problem()
    if problem is not None:
        pytest.skip(problem)
    async with (
        sim_process(str(MAC), "--assembly", "21", "--ramp-time", "0.3"),
        running_gateway(tmp_path, buses, ["cfw08"]) as gw,
    ):
        yield gw


async def test_cfw08_in_another_process_run_by_zenoh_read_by_modbus(gateway: Gateway) -> None:
    with gateway.client.subscribe(gateway.state_key("cfw08")) as states:
        await gateway.client.settled(PREFIX)
        await gateway.command("cfw08", {"run": True, "speed_rpm": 900})
        s = parsed(await states.auntil(lambda g: parsed(g).speed_rpm == 900.0, TIMEOUT))
        assert s.at_reference and s.online and s.status.label == "running"
    regs = await gateway.inputs(UNIT)
    assert regs[0] & 0b10111 == 0b10111  # online, ready, running, at reference
    assert (regs[2], regs[19], regs[20]) == (900, 4, MAC)  # speed, CFW-08, MAC
    await gateway.command("cfw08", {"run": False})
    s = await gateway.wait_for("cfw08", lambda s: not s.running and s.speed_rpm == 0.0)
    assert s.online and s.status.label == "ready"
    diag = await gateway.diagnostics("dn")
    assert (diag["interface"], diag["channel"], diag["simulated"]) == ("socketcan", VCAN, False)
