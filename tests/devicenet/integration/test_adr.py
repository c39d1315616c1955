"""Automatic Device Replacement (seed 6.1, issue 20): a CFW-08 appearing at MAC 63 with
the identity of a missing ``adr`` drive is re-addressed, reset and reprogrammed."""

from __future__ import annotations

from adapters.devicenet.link import LinkConfig
from adapters.devicenet.sim import SimNodeConfig
from gateway.adapter import EventKind
from gateway.model import CommState
from tests.devicenet.integration.conftest import drive, rig

REPLACEMENT = SimNodeConfig(63, serial_number=0x999)


def _online(s: object) -> bool:
    return getattr(s, "comm", None) is CommState.ONLINE


async def test_a_replacement_at_63_takes_the_missing_drives_place(can_line: LinkConfig) -> None:
    drives = [drive(5, adr=True, startup_params={"P100": 33})]
    async with rig(can_line, drives, sims=[REPLACEMENT]) as r:
        ev = await r.event(lambda e: e.kind is EventKind.CONFIG and e.text.startswith("ADR"))
        assert ev.drive_id == "d5"
        assert ev.text == (
            "ADR: a drive with the identity of d5 (serial 2457) appeared at MAC 63: set to "
            "MAC 5 and reset (seed 6.1); it is reprogrammed when it connects (startup_params)"
        )
        await r.wait("d5", _online, within=10.0)
        node = next(iter(r.sim.nodes.values()))
        assert node.mac == 5 and node.drive.params[701] == 5
        assert node.drive.params[100] == 33  # reprogrammed at connect
        assert node.identity.serial_number == 0x999


async def test_no_replacement_without_adr(can_line: LinkConfig) -> None:
    # d5 is missing and the node at 63 has its identity, but d5 has no adr; d7 (adr, other
    # product code) is missing too, so MAC 63 is looked at
    drives = [drive(5), drive(7, product_code=99, adr=True)]
    async with rig(can_line, drives, sims=[REPLACEMENT]) as r:
        await r.until(lambda: r.adapter.adr.next_look > 0, within=10.0)
        node = r.sim.nodes[63]
        assert node.mac == 63 and node.drive.params[701] == 63
        assert not [e for e in r.seen if e.text.startswith("ADR")]


async def test_identity_must_match(can_line: LinkConfig) -> None:
    drives = [drive(5, adr=True, product_code=42)]
    async with rig(can_line, drives, sims=[REPLACEMENT]) as r:
        await r.until(lambda: r.adapter.adr.next_look > 0, within=10.0)
        assert r.sim.nodes[63].mac == 63
        assert r.hub.state("d5").comm is not CommState.ONLINE


async def test_two_matching_missing_drives_are_ambiguous(can_line: LinkConfig) -> None:
    drives = [drive(5, adr=True), drive(6, adr=True)]
    async with rig(can_line, drives, sims=[REPLACEMENT]) as r:
        ev = await r.event(lambda e: e.kind is EventKind.CONFIG and "several" in e.text)
        assert ev.text == (
            "ADR: the drive at MAC 63 (serial 2457) matches several missing drives (d5, d6): "
            "not re-addressed"
        )
        assert r.sim.nodes[63].mac == 63
