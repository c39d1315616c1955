"""How often the CFW-08 profile reads the drive's status and sources (docs/decisions/0106).

P070, P081 and P313 at every status poll; of P220-P231 only what says whether the drive obeys
the network on the pair in use, the others every fifth poll and at the next poll after the
I/O showed the drive's situation changing. A fake port answers from a simulated CFW-08's
objects, as the drive answers on the line.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from adapters.devicenet.cfw08 import In71
from adapters.devicenet.cfw08.assemblies import parameter_of
from adapters.devicenet.cfw08.profile import SOURCE_PARAMS, SOURCES_EVERY, Cfw08Profile
from adapters.devicenet.codec.explicit import GetAttributeSingle, Request, Response
from adapters.devicenet.sim import objects as sim_objects
from adapters.devicenet.sim.node import Cfw08Node, SimNodeConfig
from gateway.adapter import EventKind
from gateway.model import DesiredCommand
from tests.devicenet.test_cfw08_safety import MAC, profile


class SimPort:
    """A DrivePort whose requests a simulated node answers; the parameters read, in turn."""

    bitrate = 125_000
    io_timeout = 0.8

    def __init__(self, node: Cfw08Node) -> None:
        self.node = node
        self.read: list[int | None] = []
        self.events: list[str] = []

    async def request(self, body: Request) -> Response:
        if isinstance(body, GetAttributeSingle):
            self.read.append(parameter_of(body.class_id, body.attribute_id))
        return sim_objects.handle(self.node, body)

    def event(self, kind: EventKind, text: str, **data: Any) -> None:
        self.events.append(text)

    def capabilities_changed(self) -> None:
        return None

    def values_changed(self) -> None:
        return None


def polls(p: Cfw08Profile, port: SimPort, count: int) -> list[list[int | None]]:
    """The parameters (None: not a parameter) each of ``count`` status polls read."""
    out = []
    for _ in range(count):
        port.read.clear()
        asyncio.run(p.poll_status(port))
        out.append(list(port.read))
    return out


def sim_port(p710: int) -> SimPort:
    node = Cfw08Node(SimNodeConfig(MAC, p710=p710))
    node.power_on(0.0)
    return SimPort(node)


STATUS = [70, 81, 313]


@pytest.mark.parametrize(
    ("assembly", "p710", "every_poll"),
    [(21, 1, []), (100, 2, [229, 230])],
    ids=["21-71", "100-150"],
)
def test_the_sources_are_read_every_fifth_poll_but_those_of_local_control(
    assembly: int, p710: int, every_poll: list[int]
) -> None:
    """On a 125 kbit/s line of 63 CFW-08s every source at every 2 s poll took half the bus."""
    p, port = profile(assembly), sim_port(p710)
    seen = polls(p, port, 2 * SOURCES_EVERY)
    whole = [*STATUS, *SOURCE_PARAMS]
    assert seen == 2 * ([[*STATUS, *every_poll]] * (SOURCES_EVERY - 1) + [whole])


def test_20_70_reads_ctrl_from_net_at_every_poll() -> None:
    p, port = profile(20), sim_port(0)
    seen = polls(p, port, SOURCES_EVERY)
    # Control Supervisor attribute 15 is not a parameter (None), read at every poll
    assert seen[:-1] == [[*STATUS, None]] * (SOURCES_EVERY - 1)
    assert seen[-1] == [*STATUS, *SOURCE_PARAMS, None]


def test_a_changed_situation_in_the_io_reads_every_source_at_the_next_poll() -> None:
    """The keypad's local/remote key (P220) shows in Ctrl from Net of 71 at once: the sources
    of the new situation are read at the next poll, not up to five polls later."""
    p, port = profile(21), sim_port(1)
    p.inputs(In71(ready=True, ctrl_from_net=True, drive_state=3).encode(), DesiredCommand())
    assert polls(p, port, 1) == [STATUS]
    p.inputs(In71(ready=True, ctrl_from_net=True, drive_state=3).encode(), DesiredCommand())
    assert polls(p, port, 1) == [STATUS]  # the same situation: nothing more
    p.inputs(In71(ready=True, ctrl_from_net=False, drive_state=3).encode(), DesiredCommand())
    assert polls(p, port, 2) == [[*STATUS, *SOURCE_PARAMS], STATUS]
    p.inputs(In71(ready=True, ctrl_from_net=False, ref_from_net=True).encode(), DesiredCommand())
    assert polls(p, port, 1) == [[*STATUS, *SOURCE_PARAMS]]
