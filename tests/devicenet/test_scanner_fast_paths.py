"""The scanner's short cuts for steady nodes change nothing: ``soonest`` is the minimum of
``deadlines``, and a node ``idle_until`` now has a tick that does nothing. Checked at every
step of lines that come up, poll, keep their explicit connections alive, lose a node to
inactivity and get it back, and carry explicit requests."""

from __future__ import annotations

import copy
from dataclasses import replace
from typing import Any

import pytest

from adapters.devicenet.codec.cip import CipClass
from adapters.devicenet.codec.explicit import GetAttributeSingle
from adapters.devicenet.codec.objects import IdentityAttribute
from adapters.devicenet.scanner import Scanner
from adapters.devicenet.scanner.node import Node
from tests.devicenet.test_scanner import FAST, line

KEEPALIVES = replace(FAST, explicit_epr=0.1)  # keep-alives every 50 ms


def _state(scanner: Scanner, node: Node) -> Any:
    """What a tick could change: the node's fields and what the line has to send."""
    fields = {name: copy.copy(getattr(node, name)) for name in Node.__slots__}
    fields["queue"] = list(node.queue)
    fields["figures"] = node.figures.to_json()
    for name in ("reassembler", "io_reassembler"):
        part = getattr(node, name)
        fields[name] = (part.in_progress, part.deadline)
    return fields, list(scanner._ctx.out)


@pytest.fixture
def checked(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    counts = {"soonest": 0, "idle": 0}
    step = Scanner.step

    def checking_step(self: Scanner, now: float, event: Any = None) -> Any:
        machine = self.machine
        for node in self.nodes.values():
            times = machine.deadlines(node)
            assert machine.soonest(node) == (min(times) if times else None)
            counts["soonest"] += 1
            if self.online and machine.idle_until(node, now):
                before = _state(self, node)
                machine.ticks[node.phase](node, now)  # a no-op, so the real step is unchanged
                assert _state(self, node) == before
                counts["idle"] += 1
        return step(self, now, event)

    monkeypatch.setattr(Scanner, "step", checking_step)
    return counts


def test_steady_nodes_short_cuts_agree_with_the_general_path(checked: dict[str, int]) -> None:
    lin = line(3, 4, 5, config=KEEPALIVES)
    lin.run(0.5)
    lin.sims[4].power_off()  # inactivity, then back
    lin.run(0.4)
    lin.power_on(lin.sims[4])
    lin.run(0.6)
    get = GetAttributeSingle(CipClass.IDENTITY, 1, IdentityAttribute.STATUS)
    for mac in (3, 5):
        lin.scanner.submit(mac, get)
    lin.run(0.3)
    assert sorted(m for m, n in lin.scanner.nodes.items() if n.phase.value == "online") == [3, 4, 5]
    assert checked["idle"] > 100 and checked["soonest"] > 1000
