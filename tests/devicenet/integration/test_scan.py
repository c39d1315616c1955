"""``drive-gateway devicenet scan`` against simulated CFW-08s on python-can (issue 20)."""

from __future__ import annotations

import asyncio
import uuid
from pathlib import Path

import pytest

from adapters.devicenet.cli import ScanRefused, scan_line
from adapters.devicenet.link import LinkConfig
from adapters.devicenet.scanner.probe import NodeInfo, ProbeConfig, Progress
from adapters.devicenet.sim import SimNodeConfig, SimPhase, SimRunner
from gateway.model import CommState
from tests.devicenet.integration.conftest import drive, rig
from tests.support.timing import scaled

CFW08_EDS = Path(__file__).resolve().parents[3] / "config" / "eds" / "cfw08-test.eds"
FAST = {"timeout": scaled(0.1), "dupmac_timeout": scaled(0.05), "window": 8}


async def _sims(line: LinkConfig, macs: list[int]) -> tuple[SimRunner, asyncio.Task[None]]:
    runner = SimRunner(line, [SimNodeConfig(m, serial_number=0x100 + m) for m in macs])
    task = asyncio.create_task(runner.run(), name="sim")
    await asyncio.wait_for(runner.started.wait(), 5)
    checking = SimPhase.CHECKING
    await runner.until(lambda: all(n.phase is not checking for n in runner.nodes.values()))
    return runner, task


async def test_scan_finds_every_node_with_its_identity(can_line: LinkConfig) -> None:
    runner, task = await _sims(can_line, [3, 17, 63])
    seen: list[Progress] = []
    try:
        nodes = await scan_line(can_line, ProbeConfig(**FAST), seen.append)  # type: ignore[arg-type]
        assert [n.mac for n in nodes] == [3, 17, 63]
        assert nodes[1] == NodeInfo(
            mac=17,
            vendor_id=0x355,
            product_type=2,
            product_code=8,
            revision=(4, 6),
            serial_number=0x111,
            product_name="CFW-08",
        )
        assert len(seen) == 63 and seen[-1].done == 63  # every MAC but the tool's own
        assert {p.mac for p in seen if p.found is not None} == {3, 17, 63}
        # what the scan allocated is released: each node is free for a master
        for mac in (3, 17, 63):
            assert not runner.nodes[mac].allocation
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_scan_then_the_gateway_connects(can_line: LinkConfig) -> None:
    channel = LinkConfig(can_line.interface, can_line.channel)
    async with rig(channel, [drive(9)], settle=True) as r:
        r.task.cancel()  # the gateway is stopped while the scan runs
        await asyncio.gather(r.task, return_exceptions=True)
        nodes = await scan_line(channel, ProbeConfig(macs=(9,), **FAST))  # type: ignore[arg-type]
        assert [n.product_name for n in nodes] == ["CFW-08"]


async def test_scan_refuses_beside_a_running_scanner(can_line: LinkConfig) -> None:
    async with rig(can_line, [drive(4)]) as r:
        await r.wait("d4", lambda s: s.comm is CommState.ONLINE)
        before = r.adapter.diagnostics()["drives"]["d4"]["allocations"]
        # the running scanner must answer the tool's Duplicate MAC ID check in time: the
        # fact sheet's 1 s (2.3), not the fast scans' 50 ms (a loaded machine missed that)
        config = {**FAST, "dupmac_timeout": scaled(1.0)}
        with pytest.raises(ScanRefused, match="MAC ID 0 is taken on the line"):
            await scan_line(can_line, ProbeConfig(**config))  # type: ignore[arg-type]
        state = r.hub.state("d4")
        assert state.comm is CommState.ONLINE
        assert r.adapter.diagnostics()["drives"]["d4"]["allocations"] == before


def test_unused_channel_is_empty() -> None:
    line = LinkConfig("virtual", f"dn-{uuid.uuid4().hex[:10]}")
    nodes = asyncio.run(scan_line(line, ProbeConfig(macs=(1, 2), **FAST)))  # type: ignore[arg-type]
    assert nodes == ()


def test_cli_scan_of_an_empty_line(capsys: pytest.CaptureFixture[str]) -> None:
    from gateway.cli import main

    channel = f"dn-{uuid.uuid4().hex[:10]}"
    argv = ["devicenet", "scan", "--interface", "virtual", "--channel", channel]
    assert main([*argv, "--nodes", "1-2", "--timeout", "0.05", "--json"]) == 0
    out, err = capsys.readouterr()
    assert out.strip() == "[]"
    assert "scanning MAC  2 (2/2)" in err


def test_sim_cli_takes_an_eds() -> None:
    import argparse

    from adapters.devicenet.cli import add_sim, node_configs

    parser = argparse.ArgumentParser()
    add_sim(parser.add_subparsers())
    args = parser.parse_args(["devicenet", "--nodes", "4", "--eds", str(CFW08_EDS)])
    (config,) = node_configs(args)
    assert config.identity is not None and config.identity.revision == (4, 6)
    assert config.io_sizes == (4, 4)
    with pytest.raises(SystemExit):
        parser.parse_args(["devicenet", "--nodes", "4", "--eds", "/nonexistent.eds"])
