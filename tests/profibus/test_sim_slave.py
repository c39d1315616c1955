"""The generic DP slave simulator (fact sheet 1.3, 1.5-1.10), request by request."""

from __future__ import annotations

from typing import Any

import pytest

from adapters.profibus.codec import dpv1
from adapters.profibus.codec.diag import SlaveDiag
from adapters.profibus.codec.dp import Dpv1Status, GlobalControl, SetPrm, SlaveSap, build_request
from adapters.profibus.codec.dp import SlaveDiagRequest as DiagReq
from adapters.profibus.codec.fdl import (
    SHORT_ACK,
    DataTelegram,
    FcbState,
    RequestFc,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    StationType,
    decode_telegram,
)
from adapters.profibus.sim.echo import ECHO_IDENT, EchoSim, echo_cfg
from adapters.profibus.sim.line import SimLine
from adapters.profibus.sim.slave import DpSlave, SlaveMode
from gateway.sim import FaultInjector
from tests.profibus.script import h

MASTER = 2


class Master:
    """Requests to one simulated slave, with the FCB kept as a master does (1.3)."""

    def __init__(self, slave: DpSlave) -> None:
        self.slave = slave
        self.fcb = FcbState()
        self.now = 0.0

    def ask(self, dsap: int | None, data: bytes = b"", *, repeat: bool = False) -> Any:
        fc = self.fcb.fc(RequestFunction.SRD_HIGH)
        ssap = None if dsap is None else (51 if dsap == 51 else 62)
        request = DataTelegram(self.slave.address, MASTER, fc, dsap, ssap, data)
        self.last = request
        reply = self.slave.handle(request, self.now)
        if reply is not None and not repeat:
            self.fcb = self.fcb.acknowledged()
        return reply

    def again(self) -> Any:
        """The same request again (a retry: same FCB)."""
        return self.slave.handle(self.last, self.now)

    def diag(self) -> SlaveDiag:
        reply = self.ask(SlaveSap.SLAVE_DIAG)
        assert isinstance(reply, DataTelegram) and reply.ssap == SlaveSap.SLAVE_DIAG
        return SlaveDiag.decode(reply.data)

    def set_prm(self, **changes: Any) -> Any:
        values: dict[str, Any] = {"ident_number": ECHO_IDENT, "wd_on": True, "wd_fact_2": 10}
        values.update(changes)
        return self.ask(SlaveSap.SET_PRM, SetPrm(dpv1=None, **values).encode())

    def start(self, size: int = 4) -> None:
        assert self.set_prm() is SHORT_ACK
        assert self.ask(SlaveSap.CHK_CFG, echo_cfg(size)) is SHORT_ACK


def echo_slave(size: int = 4, dpv1: bool = False) -> tuple[DpSlave, EchoSim]:
    device = EchoSim(size)
    slave = DpSlave(5, device)
    slave.dpv1 = dpv1  # tests speak the DP-V0 Set_Prm layout unless they ask for DP-V1
    return slave, device


def test_a_fresh_slave_asks_for_parameters() -> None:
    slave, _ = echo_slave()
    diag = Master(slave).diag()
    assert (diag.station_not_ready, diag.prm_req, diag.master_address) == (True, True, 0xFF)
    assert diag.ident_number == ECHO_IDENT
    assert slave.mode is SlaveMode.WAIT_PRM


def test_start_up_to_data_exchange_and_the_diagnosis_after_it() -> None:
    slave, device = echo_slave()
    m = Master(slave)
    m.start()
    assert slave.mode is SlaveMode.DATA_EXCH
    diag = m.diag()
    assert diag.ready_for_data_exchange and diag.wd_on and diag.master_address == MASTER
    reply = m.ask(None, h("01 02 03 04"))
    assert reply.fc == ResponseFc(ResponseStatus.DL) and reply.data == h("01 02 03 04")
    assert device.outputs == h("01 02 03 04")


def test_wrong_ident_is_a_prm_fault() -> None:
    slave, _ = echo_slave()
    m = Master(slave)
    assert m.set_prm(ident_number=0x1111) is SHORT_ACK  # faults are told by diagnosis
    diag = m.diag()
    assert diag.prm_fault and diag.prm_req and slave.mode is SlaveMode.WAIT_PRM


def test_a_device_refusing_its_user_parameters_is_a_prm_fault() -> None:
    slave, device = echo_slave()
    device.accept_prm = False
    m = Master(slave)
    m.set_prm(user_prm_data=h("AA"))
    assert m.diag().prm_fault
    assert device.user_prm == h("AA")


def test_a_wrong_configuration_is_a_cfg_fault_and_get_cfg_tells_the_right_one() -> None:
    slave, _ = echo_slave()
    m = Master(slave)
    m.set_prm()
    assert m.ask(SlaveSap.CHK_CFG, h("F1")) is SHORT_ACK
    diag = m.diag()
    assert diag.cfg_fault and slave.mode is SlaveMode.WAIT_PRM
    assert m.ask(SlaveSap.GET_CFG).data == echo_cfg(4)


def test_injected_wrong_configuration() -> None:
    slave, _ = echo_slave()
    slave.faults.wrong_cfg = h("F3")
    m = Master(slave)
    m.set_prm()
    m.ask(SlaveSap.CHK_CFG, echo_cfg(4))
    assert m.diag().cfg_fault
    assert m.ask(SlaveSap.GET_CFG).data == h("F3")


def test_a_repeated_fcb_gets_the_previous_reply_without_acting_twice() -> None:
    slave, device = echo_slave()
    m = Master(slave)
    m.start()
    first = m.ask(None, h("01 00 00 00"), repeat=True)
    exchanges = device.exchanges
    assert m.again() == first  # 1.3: a retry keeps the FCB
    assert device.exchanges == exchanges
    assert slave.counters.repeats == 1


def test_data_exchange_outside_data_exchange_is_rs() -> None:
    slave, _ = echo_slave()
    reply = Master(slave).ask(None, h("00 00 00 00"))
    assert reply.fc == ResponseFc(ResponseStatus.RS)


def test_the_watchdog_takes_the_slave_out_of_data_exchange() -> None:
    slave, device = echo_slave()
    m = Master(slave)
    m.start()  # watchdog 100 ms (1 x 10 x 10 ms)
    slave.tick(0.05)
    modes = [slave.mode]
    slave.tick(0.2)
    modes.append(slave.mode)
    assert modes == [SlaveMode.DATA_EXCH, SlaveMode.WAIT_PRM]
    assert device.comm_losses == 1 and slave.counters.comm_lost == 1
    assert slave.master is None


def test_time_the_process_stood_still_does_not_count_for_the_watchdog() -> None:
    """Issue 18: a busy machine froze the demo's process for longer than the watchdog; the
    simulated slaves (in that process) dropped out though no telegram could have come."""
    slave, _ = echo_slave()
    lines = SimLine([slave])
    m = Master(slave)
    m.start()  # watchdog 100 ms
    lines.stood_still(0.3)  # the process was not scheduled for 0.3 s
    modes = []
    slave.tick(0.35)
    modes.append(slave.mode)
    slave.tick(0.45)  # 150 ms of running time without a telegram: expired
    modes.append(slave.mode)
    assert modes == [SlaveMode.DATA_EXCH, SlaveMode.WAIT_PRM]


async def test_a_late_tick_tells_the_line_the_process_stood_still() -> None:
    import asyncio
    import time

    from adapters.profibus.sim.port import STALL, SimPort

    slave, _ = echo_slave()
    line = SimLine([slave])
    m = Master(slave)
    m.start()
    slave.watchdog = 1.0  # s
    port, _path = SimPort.on_pty(line, tick=0.01)
    loop = asyncio.get_running_loop()
    slave.last_contact = loop.time()
    port.start()
    try:
        time.sleep(15 * STALL)  # noqa: ASYNC251 - the stalled process under test
        for _ in range(1000):
            if port.stalls:
                break
            await asyncio.sleep(0.01)
        assert port.stalls >= 1
        assert slave.mode is SlaveMode.DATA_EXCH  # watchdog 1 s, stood still 1.5 s
    finally:
        port.close()


def test_global_control_clear_and_groups() -> None:
    slave, device = echo_slave()
    m = Master(slave)
    m.set_prm(group_ident=0b10)  # group 2
    m.ask(SlaveSap.CHK_CFG, echo_cfg(4))

    def broadcast(control: GlobalControl) -> None:
        request = build_request(control, da=127, sa=MASTER, fc=RequestFc(RequestFunction.SDN_HIGH))
        assert slave.handle(request, 0.0) is None  # SDN: no reply

    broadcast(GlobalControl.clear(group_select=0b01))  # group 1: not for this slave
    assert not slave.clear
    broadcast(GlobalControl.clear())
    assert slave.clear and device.comm_losses == 1 and slave.counters.clears == 1
    broadcast(GlobalControl.clear())
    assert device.comm_losses == 1  # already clear
    broadcast(GlobalControl.operate())
    assert not slave.clear
    broadcast(GlobalControl(sync=True, freeze=True))
    assert slave.sync and slave.freeze
    assert m.diag().sync_mode
    assert GlobalControl(sync=True, freeze=True) in device.global_controls


def test_dpv1_request_is_acknowledged_then_answered_on_a_poll() -> None:
    slave, device = echo_slave(dpv1=True)
    m = Master(slave)
    assert m.ask(SlaveSap.SET_PRM, SetPrm(ECHO_IDENT, dpv1=Dpv1Status()).encode()) is SHORT_ACK
    m.ask(SlaveSap.CHK_CFG, echo_cfg(4))
    write = dpv1.WriteRequest(0, 1, h("AB CD"))
    assert m.ask(SlaveSap.MSAC_C1, write.encode()) is SHORT_ACK
    answer = m.ask(SlaveSap.MSAC_C1)  # the poll
    assert dpv1.decode_response(answer.data) == dpv1.WriteResponse(0, 1, 2)
    assert m.ask(SlaveSap.MSAC_C1) is SHORT_ACK  # nothing more
    m.ask(SlaveSap.MSAC_C1, dpv1.ReadRequest(0, 7, 4).encode())
    error = dpv1.decode_response(m.ask(SlaveSap.MSAC_C1).data)
    assert error == dpv1.Dpv1ErrorResponse(dpv1.Dpv1Function.READ, 0x80, 0xB0, 0)
    assert device.records[1] == h("AB CD")


def test_dpv1_answer_delay_and_inactive_sap() -> None:
    slave, _ = echo_slave(dpv1=True)
    slave.faults.record_delay = 0.5
    m = Master(slave)
    assert m.ask(SlaveSap.MSAC_C1, dpv1.ReadRequest(0, 0, 4).encode()).fc == ResponseFc(
        ResponseStatus.RS
    )  # not in data exchange yet
    m.ask(SlaveSap.SET_PRM, SetPrm(ECHO_IDENT, dpv1=Dpv1Status()).encode())
    m.ask(SlaveSap.CHK_CFG, echo_cfg(4))
    m.ask(SlaveSap.MSAC_C1, dpv1.ReadRequest(0, 0, 4).encode())
    assert m.ask(SlaveSap.MSAC_C1) is SHORT_ACK
    m.now = 0.6
    assert m.ask(SlaveSap.MSAC_C1).data == h("5E 00 00 04 EC 00 01 00")


def test_a_dpv0_device_has_no_sap_51() -> None:
    slave, _ = echo_slave()
    m = Master(slave)
    m.start()
    reply = m.ask(SlaveSap.MSAC_C1, dpv1.ReadRequest(0, 0, 4).encode())
    assert reply.fc == ResponseFc(ResponseStatus.RS)


def test_fdl_status_answer_and_unknown_sap() -> None:
    slave, _ = echo_slave()
    status = slave.handle(DataTelegram(5, MASTER, RequestFc(RequestFunction.FDL_STATUS)), 0.0)
    assert status is not None and status.encode() == h("10 02 05 00 07 16")
    reply = Master(slave).ask(SlaveSap.SET_SLAVE_ADD, h("07 EC 00 00"))
    assert reply.fc == ResponseFc(ResponseStatus.RS)


def test_power_cycle_silences_then_restarts_in_wait_prm() -> None:
    slave, device = echo_slave()
    m = Master(slave)
    m.start()
    slave.power_cycle(1.0, off_time=0.5)
    m.now = 1.2
    assert m.ask(SlaveSap.SLAVE_DIAG) is None
    m.now = 1.6
    assert m.diag().prm_req
    assert device.power_cycles == 1


def test_dh_once_per_new_diagnosis_while_an_alert() -> None:
    slave, device = echo_slave()
    m = Master(slave)
    m.start()
    device.diag = h("03 01 02")
    assert m.ask(None, bytes(4)).fc.status is ResponseStatus.DH
    diag_reply = m.ask(SlaveSap.SLAVE_DIAG)
    assert diag_reply.data[6:] == h("03 01 02")
    assert SlaveDiag.decode(diag_reply.data).ext_diag
    assert m.ask(None, bytes(4)).fc.status is ResponseStatus.DL  # read: no more DH
    device.diag_alert = False  # worth no alarm (like a changed parameter)
    device.diag = h("03 00 07")
    assert m.ask(None, bytes(4)).fc.status is ResponseStatus.DL


def test_the_line_dispatches_by_address_and_broadcasts_to_all() -> None:
    line = SimLine([DpSlave(5, EchoSim()), DpSlave(6, EchoSim())])
    with pytest.raises(ValueError, match="two simulated slaves at address 5"):
        line.add(DpSlave(5, EchoSim()))
    request = build_request(DiagReq(), da=6, sa=MASTER, fc=RequestFc(RequestFunction.SRD_HIGH))
    wire = request.encode()
    out = line.receive(wire[:4], 0.0) + line.receive(wire[4:], 0.0)  # split in two reads
    (reply,) = out
    telegram = decode_telegram(reply.data)
    assert isinstance(telegram, DataTelegram) and telegram.sa == 6
    assert line.receive(b"\x00\xff", 0.0) == [] and line.counters.garbage == 1
    assert line.receive(wire, 0.0)[0].data == reply.data  # garbage skipped, request found


def test_line_faults_drop_delay_and_noise() -> None:
    line = SimLine([DpSlave(5, EchoSim())], FaultInjector(seed=1, drop_rate=1.0))
    wire = DataTelegram(5, MASTER, RequestFc(RequestFunction.FDL_STATUS)).encode()
    assert line.receive(wire, 0.0) == [] and line.counters.dropped == 1
    line.faults = FaultInjector(delay=0.25)
    assert line.receive(wire, 1.0)[0].at == 1.25
    line.faults = FaultInjector(seed=3, bit_error_rate=1.0)
    line.faults = FaultInjector()
    line[5].injector.bit_error_rate = 1.0
    (noisy,) = line.receive(wire, 2.0)
    assert noisy.data != h("10 02 05 00 07 16")


def test_station_type_of_the_status_reply() -> None:
    slave, _ = echo_slave()
    status = slave.handle(DataTelegram(5, MASTER, RequestFc(RequestFunction.FDL_STATUS)), 0.0)
    assert isinstance(status, DataTelegram)
    assert status.fc == ResponseFc(ResponseStatus.OK, StationType.SLAVE)
