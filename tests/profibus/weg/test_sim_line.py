"""The simulated WEG drives and the line itself (issue 36: the audits' rows C11-51/C7-36/
C3-23, C11-58/C7-42/C3-29, C11-72/C7-48/C3-40): the detected baud rate in P0963 / P754,
the DS_Write positive answer with length 0, and SYNC/UNSYNC, FREEZE/UNFREEZE as the
manuals describe them (CFW-11 4.1.2, CFW700 5.1.2, CFW320 5.1.2)."""

from __future__ import annotations

import struct

import pytest

from adapters.profibus.codec import dpv1
from adapters.profibus.codec.dp import Dpv1Status, GlobalControl, SetPrm, SlaveSap
from adapters.profibus.codec.fdl import SHORT_ACK, DataTelegram, RequestFc, RequestFunction
from adapters.profibus.sim.echo import EchoSim
from adapters.profibus.sim.simulated import SimulatedLine
from adapters.profibus.sim.slave import DpSlave
from adapters.profibus.weg.sim.drive import Cfw11Sim, Cfw320Sim, Cfw700Sim, WegSim
from gateway.config import parse
from tests.profibus.weg.test_sim import NET, RUN_FWD, exchange, run_for

MASTER = 2


def ask(slave: DpSlave, dsap: int | None, data: bytes, fcb: bool) -> object:
    fc = RequestFc(RequestFunction.SRD_HIGH, fcb=fcb, fcv=True)
    ssap = None if dsap is None else (51 if dsap == 51 else 62)
    return slave.handle(DataTelegram(slave.address, MASTER, fc, dsap, ssap, data), 0.0)


def started(sim: WegSim, baudrate: int | None) -> DpSlave:
    slave = DpSlave(sim.address, sim, baudrate)
    prm = SetPrm(sim.ident_number, wd_on=True, wd_fact_2=100, dpv1=Dpv1Status())
    assert ask(slave, SlaveSap.SET_PRM, prm.encode(), True) is SHORT_ACK
    assert ask(slave, SlaveSap.CHK_CFG, sim.expected_cfg(), False) is SHORT_ACK
    return slave


@pytest.mark.parametrize(
    ("model", "param", "baudrate", "code"),
    [
        (Cfw11Sim, 963, 1_500_000, 6),
        (Cfw11Sim, 963, 45_450, 11),
        (Cfw700Sim, 963, 12_000_000, 9),
        (Cfw320Sim, 754, 19_200, 1),
        (Cfw320Sim, 754, 500_000, 4),
    ],
)
def test_the_detected_baud_rate_is_the_line_s(
    model: type[WegSim], param: int, baudrate: int, code: int
) -> None:
    sim = model()
    started(sim, baudrate)
    assert sim.param(param) == code


async def test_the_simulated_line_gives_its_slaves_the_bus_baud_rate() -> None:
    drives = [{"id": "a", "device": "CFW-11", "address": 3}]
    table = {"adapter": "profibus", "simulate": True, "baudrate": 187500, "drives": drives}
    config = parse({"buses": {"pb": table}}, "baud.toml")
    links = SimulatedLine(config.buses[0])
    links.start()
    try:
        assert links.line is not None
        slave = links.line[3]
        assert slave.baudrate == 187500
        started_again = started(slave.device, slave.baudrate)  # type: ignore[arg-type]
        assert started_again.device.param(963) == 3  # type: ignore[attr-defined]
    finally:
        links.close()


def test_without_a_known_rate_the_factory_value_stays() -> None:
    sim = Cfw11Sim()
    started(sim, None)
    assert sim.param(963) == 1  # CFW-11 "Padrão: 1"
    sim.baud_detected(250_000)  # no DP rate
    assert sim.param(963) == 5  # not detected


def test_a_ds_write_is_answered_with_length_0() -> None:
    sim = Cfw11Sim()
    slave = started(sim, 1_500_000)
    write = dpv1.WriteRequest(0, 48, struct.pack(">HH", 100, 50))  # P0100 = 5.0 s
    assert ask(slave, SlaveSap.MSAC_C1, write.encode(), True) is SHORT_ACK
    answer = ask(slave, SlaveSap.MSAC_C1, b"", False)
    assert isinstance(answer, DataTelegram)
    assert answer.data == bytes([0x5F, 0, 48, 0])
    assert dpv1.decode_response(answer.data) == dpv1.WriteResponse(0, 48, 0)
    assert sim.param(100) == 50


def test_another_device_still_answers_the_length_it_took() -> None:
    slave = DpSlave(5, EchoSim())
    assert slave.device.write_answer_length(3) == 3


STOP = RUN_FWD & ~0x0001  # run bit 0 = 0: ramp stop


@pytest.mark.parametrize("model", [Cfw11Sim, Cfw700Sim, Cfw320Sim])
def test_sync_holds_the_outputs_until_the_next_sync(model: type[WegSim]) -> None:
    sim = model(params=NET)
    now = run_for(sim, 0.0, 1.0, RUN_FWD, 8192)
    assert sim.running
    sim.global_control(GlobalControl(sync=True), now)
    now = run_for(sim, now, 1.0, STOP, 0)  # stored, not taken
    assert sim.running and sim.net.run
    sim.global_control(GlobalControl(sync=True), now)  # taken now, still synced
    assert not sim.net.run
    now = run_for(sim, now, 0.5, RUN_FWD, 8192)
    assert not sim.net.run  # held again
    sim.global_control(GlobalControl(unsync=True), now)
    assert sim.net.run  # the UNSYNC takes the stored words and ends the function
    run_for(sim, now, 0.2, STOP, 0)
    assert not sim.net.run  # taken at once again


@pytest.mark.parametrize("model", [Cfw11Sim, Cfw700Sim, Cfw320Sim])
def test_freeze_holds_the_inputs_until_the_next_freeze(model: type[WegSim]) -> None:
    sim = model(params=NET)
    now = run_for(sim, 0.0, 0.1, RUN_FWD, 8192)
    sim.global_control(GlobalControl(freeze=True), now)
    frozen = exchange(sim, now, RUN_FWD, 8192)
    now = run_for(sim, now, 1.0, RUN_FWD, 8192)
    assert exchange(sim, now, RUN_FWD, 8192) == frozen  # the speed moved, the inputs did not
    sim.global_control(GlobalControl(freeze=True), now)
    again = exchange(sim, now + 0.5, RUN_FWD, 8192)
    assert again != frozen and again[1] > frozen[1]
    sim.global_control(GlobalControl(unfreeze=True), now + 0.5)
    assert exchange(sim, now + 1.0, RUN_FWD, 8192)[1] > again[1]


def test_a_lost_communication_ends_sync_and_freeze() -> None:
    sim = Cfw11Sim(params=NET)
    slave = started(sim, 1_500_000)
    now = run_for(sim, 0.0, 0.1, RUN_FWD, 8192)
    sim.global_control(GlobalControl(sync=True, freeze=True), now)
    sim.comm_lost(now)
    assert not sim.sync_freeze.synced and sim.sync_freeze.frozen is None
    assert slave.device is sim
