"""Drives configured from an EDS against simulators configured from the same file
(issue 20): identity and sizes from the file reach data exchange; a drive whose Identity
object differs from its EDS is refused with an event naming what differs."""

from __future__ import annotations

from pathlib import Path

from adapters.devicenet.link import LinkConfig
from adapters.devicenet.options import load_eds
from adapters.devicenet.sim import SimNodeConfig
from adapters.devicenet.sim.objects import identity_from_eds as sim_identity
from gateway.adapter import EventKind
from gateway.model import CommState
from tests.devicenet.integration.conftest import drive, rig

ROOT = Path(__file__).resolve().parents[3]
CFW08_EDS = ROOT / "config" / "eds" / "cfw08-test.eds"


def _variant(tmp_path: Path, old: str, new: str) -> Path:
    text = CFW08_EDS.read_text()
    assert old in text
    path = tmp_path / "variant.eds"
    path.write_text(text.replace(old, new, 1))
    return path


async def test_drive_and_simulator_from_one_eds(can_line: LinkConfig) -> None:
    async with rig(can_line, [drive(5, eds=str(CFW08_EDS))]) as r:
        state = await r.wait("d5", lambda s: s.comm is CommState.ONLINE)
        assert state.values["P313"] == 2
        node = r.sim.nodes[5]
        assert node.identity.product_name == "CFW-08" and node.identity.revision == (4, 6)
        diag = r.adapter.diagnostics()["drives"]["d5"]
        assert diag["product_name"] == "CFW-08" and diag["configured"]
        raw = await r.adapter.read_param("d5", 100, 0)
        info = r.adapter.param_info("d5", 100, raw)
        assert info == {"name": "Acceleration time", "unit": "s", "scaled": raw / 10}
        assert r.adapter.param_info("d5", 222, 0) == {}
        # the same through the drive's capabilities, the lookup the front ends use
        table = r.hub.capabilities("d5").params
        assert (table[100].label, table[100].name, table[100].unit) == (
            "P100",
            "Acceleration time",
            "s",
        )
        assert table[100].scaled(raw) == raw / 10 and 222 not in table


async def test_simulator_identity_follows_its_eds(can_line: LinkConfig, tmp_path: Path) -> None:
    eds = _variant(tmp_path, "ProdCode = 8;", "ProdCode = 77;")
    async with rig(can_line, [drive(6, eds=str(eds))]) as r:
        await r.wait("d6", lambda s: s.comm is CommState.ONLINE)
        assert r.sim.nodes[6].identity.product_code == 77


def _sim_from(mac: int, path: Path) -> SimNodeConfig:
    return SimNodeConfig(mac, identity=sim_identity(load_eds(path)))


async def test_revision_differs_from_the_eds(can_line: LinkConfig, tmp_path: Path) -> None:
    eds = _variant(tmp_path, "MajRev = 4;", "MajRev = 5;")
    sims = [_sim_from(3, CFW08_EDS)]
    async with rig(can_line, [drive(3, eds=str(eds))], sims=sims) as r:
        ev = await r.event(lambda e: e.kind is EventKind.CONFIG and "identity" in e.text)
        assert ev.text == (
            "node 3: identity mismatch: revision 4.6, expected 5.6 (major 5, minor 6 or "
            "later): I/O refused"
        )
        assert r.hub.state("d3").comm is not CommState.ONLINE


async def test_older_minor_revision_is_refused(can_line: LinkConfig, tmp_path: Path) -> None:
    eds = _variant(tmp_path, "MinRev = 6;", "MinRev = 7;")
    async with rig(can_line, [drive(3, eds=str(eds))], sims=[_sim_from(3, CFW08_EDS)]) as r:
        ev = await r.event(lambda e: e.kind is EventKind.CONFIG and "identity" in e.text)
        assert "revision 4.6, expected 4.7" in ev.text


async def test_newer_minor_revision_is_accepted(can_line: LinkConfig, tmp_path: Path) -> None:
    eds = _variant(tmp_path, "MinRev = 6;", "MinRev = 2;")
    async with rig(can_line, [drive(3, eds=str(eds))], sims=[_sim_from(3, CFW08_EDS)]) as r:
        await r.wait("d3", lambda s: s.comm is CommState.ONLINE)


async def test_product_type_differs_from_the_eds(can_line: LinkConfig, tmp_path: Path) -> None:
    eds = _variant(tmp_path, "ProdType = 2;", "ProdType = 3;")
    async with rig(can_line, [drive(4, eds=str(eds))], sims=[_sim_from(4, CFW08_EDS)]) as r:
        ev = await r.event(lambda e: e.kind is EventKind.CONFIG and "identity" in e.text)
        assert ev.text == "node 4: identity mismatch: product type 2, expected 3: I/O refused"
