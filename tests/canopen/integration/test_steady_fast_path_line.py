"""The steady fast path on a simulated CANopen line (docs/decisions/0098): a run and then a
stop reach a quiet node's RPDO1 within the next SYNC cycles, told by the hub, not at the
next refresh."""

from __future__ import annotations

from adapters.canopen.codec.cia402 import State
from gateway.model import CommState, DriveCommand, Source
from tests.canopen.integration.conftest import drive, rig

CYCLES = 8  # SYNC cycles within which a command has reached the drive: the CiA 402 steps
# take 3 to 4 (each waits for the drive's TPDO1), one more now and then on a loaded machine;
# the refresh, which would carry a command the hub did not tell, is 50 (1 s at 20 ms)


async def test_a_run_and_a_stop_reach_a_quiet_nodes_rpdo_within_the_next_cycles() -> None:
    async with rig([drive(5)]) as r:
        await r.wait("d5", lambda s: s.comm is CommState.ONLINE)
        engine = r.adapter.engine
        assert engine is not None
        node = engine.nodes[5]
        await r.until(lambda: node.quiet)  # its repeated TPDO1s no longer handled
        sim = r.sim.node(5)
        syncs = engine.figures["syncs_tx"]
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=True, speed_rpm=600.0))
        await r.until(lambda: sim.drive.state is State.OPERATION_ENABLED)
        assert engine.figures["syncs_tx"] - syncs <= CYCLES
        await r.until(lambda: node.quiet)
        syncs = engine.figures["syncs_tx"]
        r.hub.submit("d5", Source.MODBUS, DriveCommand(run=False))
        await r.until(lambda: sim.drive.state is not State.OPERATION_ENABLED)
        assert engine.figures["syncs_tx"] - syncs <= CYCLES
