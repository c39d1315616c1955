"""The tests' free ports (tests/support/net.py) stay out of the kernel's ephemeral range,
where an outgoing connection could take one before the server under test binds it."""

from __future__ import annotations

from tests.support import net


def test_free_ports_are_below_the_ephemeral_range_and_never_repeated() -> None:
    low = int(net.EPHEMERAL_RANGE.read_text().split()[0])
    ports = [net.free_port() for _ in range(200)]
    assert len(set(ports)) == len(ports)
    assert all(max(1024, low - net.SPAN) <= p < low for p in ports)
