"""The master engine against simulated slaves, in fake time (fact sheet 1.1, 1.3, 1.5-1.10)."""

from __future__ import annotations

import dataclasses

import pytest

from adapters.profibus.codec.diag import SlaveDiag
from adapters.profibus.codec.dp import GlobalControl
from adapters.profibus.codec.fdl import SHORT_ACK, DataTelegram, ResponseFc, ResponseStatus
from adapters.profibus.master import (
    DiagnosisRead,
    FaultKind,
    InputsReceived,
    LineMode,
    Master,
    RecordDone,
    RecordFailure,
    SlaveDown,
    SlaveFault,
    SlaveState,
    SlaveStateChanged,
    SlaveUp,
)
from adapters.profibus.master.figures import Samples
from adapters.profibus.sim.slave import SlaveMode
from gateway.errors import FrameEncodeError
from tests.profibus.script import Script
from tests.profibus.wire import FAST_BUS, Wire, echo_line, echo_params

DE = SlaveState.DATA_EXCHANGE


def wire_for(present: list[int], configured: list[int] | None = None, **bus: object) -> Wire:
    params = dataclasses.replace(FAST_BUS, **bus) if bus else FAST_BUS  # type: ignore[arg-type]
    master = Master(params, [echo_params(a) for a in configured or present])
    return Wire(master, echo_line(present))


def all_in(w: Wire, *addresses: int, state: SlaveState = DE) -> bool:
    return all(w.master.state_of(a) is state for a in addresses)


# ---------------------------------------------------------------------------------------
# start-up (1.5)


def test_start_up_goes_through_every_step_in_order() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    steps = [(a.old, a.new) for a in w.of(SlaveStateChanged)]
    assert steps == [
        (SlaveState.WAIT_DIAG, SlaveState.SET_PRM),
        (SlaveState.SET_PRM, SlaveState.CHK_CFG),
        (SlaveState.CHK_CFG, SlaveState.WAIT_READY),
        (SlaveState.WAIT_READY, DE),
    ]
    assert w.of(SlaveUp) == [SlaveUp(5)]
    assert w.line[5].mode is SlaveMode.DATA_EXCH
    assert w.line[5].master == 2
    assert w.line[5].watchdog == pytest.approx(0.1)  # sent in Set_Prm (1.6)


def test_outputs_go_out_and_inputs_come_back() -> None:
    w = wire_for([5, 6])
    assert w.run_until(lambda: all_in(w, 5, 6), 1.0)
    w.master.set_outputs(5, bytes([1, 2, 3, 4]))
    w.run(0.02)
    last = {a.address: a.data for a in w.of(InputsReceived)}
    assert last == {5: bytes([1, 2, 3, 4]), 6: bytes(4)}
    with pytest.raises(FrameEncodeError, match="takes 4 output bytes"):
        w.master.set_outputs(5, b"\x01")


def test_first_exchange_waits_for_the_callers_outputs() -> None:
    """SlaveUp ends the turn: the caller sets outputs before the first Data_Exchange."""
    w = wire_for([5])
    assert w.run_until(lambda: bool(w.of(SlaveUp)), 1.0)
    w.master.set_outputs(5, bytes([9, 9, 9, 9]))
    w.run(0.01)
    assert w.line[5].device.exchanges > 0  # type: ignore[attr-defined]
    assert w.of(InputsReceived)[0].data == bytes([9, 9, 9, 9])


def test_outputs_stay_pending_until_a_data_exchange_carries_them() -> None:
    w = wire_for([5], cycle_time=0.002)
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.run(0.01)
    assert not w.master.outputs_pending(5)
    w.master.set_outputs(5, bytes([7, 7, 7, 7]))
    assert w.master.outputs_pending(5)
    sent = len(w.sent)
    assert w.run_until(lambda: not w.master.outputs_pending(5), 0.01)
    assert bytes([7, 7, 7, 7]) in w.sent[-1][1]  # the telegram that took them
    assert len(w.sent) == sent + 1


def test_a_caller_minding_pending_outputs_never_loses_one() -> None:
    """Outputs computed on every reply, replies now on time (the next Data_Exchange waits
    for the cycle time), now late (it goes out TSYN after the reply: decided only once the
    line was idle, so the caller has seen the reply first): every value computed goes out,
    in order, none replaced unsent."""
    w = wire_for([5], cycle_time=0.001)  # a reply takes 0.63 ms, late 1.23 ms (TSL 1.69)
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    computed: list[int] = []
    skipped = 0

    def caller(action: object) -> None:
        nonlocal skipped
        if not isinstance(action, InputsReceived):
            return
        w.late_by = 0.0006 if len(computed) % 3 == 0 else 0.0
        if w.master.outputs_pending(5):
            skipped += 1
            return
        computed.append(len(computed) + 1)
        w.master.set_outputs(5, computed[-1].to_bytes(2, "big") + bytes(2))

    w.on_action = caller
    w.run(0.5)
    # Data_Exchange to 5: SD2 without SAP (fact sheet 1.2), the outputs from byte 7
    carried = [
        int.from_bytes(d[7:9], "big")
        for _, d in w.sent
        if d[0] == 0x68 and d[4] == 5 and len(d) == 13
    ]
    values = [v for i, v in enumerate(carried) if v and (i == 0 or carried[i - 1] != v)]
    assert len(computed) > 50 and skipped >= 0
    assert values == computed[: len(values)] and len(values) >= len(computed) - 1


def test_an_absent_slave_is_reported_and_does_not_stall_the_others() -> None:
    w = wire_for([5, 6], configured=[5, 6, 9], cycle_time=0.002)
    assert w.run_until(lambda: all_in(w, 5, 6) and all_in(w, 9, state=SlaveState.ABSENT), 1.0)
    w.clear()
    w.run(1.0)
    exchanges = [a.address for a in w.of(InputsReceived)]
    assert exchanges.count(5) > 300 and exchanges.count(6) > 300
    probes = [t for t, d in w.sent if d[4] & 0x7F == 9]
    # probed once per absent_retry (0.2 s), one try each: it costs little of the cycle
    assert 4 <= len(probes) <= 6
    assert w.master.slave_figures(9).requests == len(probes) + 1
    assert w.master.live_list() == [5, 6]


def test_a_full_line_of_125_slaves_with_one_missing() -> None:
    """1.2: stations 0..125; with the master at 2 that is 125 slaves on one line."""
    configured = [a for a in range(126) if a != 2]
    present = [a for a in configured if a != 77]
    master = Master(FAST_BUS, [echo_params(a, watchdog=1.0) for a in configured])
    w = Wire(master, echo_line(present))
    with pytest.raises(FrameEncodeError, match=r"outside 0\.\.125"):
        Master(FAST_BUS, [echo_params(126)])
    assert w.run_until(lambda: all_in(w, *present) and all_in(w, 77, state=SlaveState.ABSENT), 5.0)
    w.clear()
    w.master.figures.cycle = Samples()
    w.run(0.5)
    counts = {a: 0 for a in present}
    for a in w.of(InputsReceived):
        counts[a.address] += 1
    assert min(counts.values()) >= 4  # every present slave keeps exchanging
    # Felser: (380 + 300 x 124 + 11 x 8 x 124) bit times at 500 kbit/s = 97 ms, and the
    # absent slave costs one slot time per absent_retry at most
    assert w.master.figures.cycle.median < 0.1
    assert all_in(w, *present)
    assert w.master.live_list() == present


def test_the_cycle_is_bounded_by_the_slot_time_of_an_absent_slave() -> None:
    w = wire_for([5], configured=[5, 9])
    assert w.run_until(lambda: all_in(w, 5) and all_in(w, 9, state=SlaveState.ABSENT), 1.0)
    w.run(0.01)  # the start-up cycle ends
    w.master.figures.cycle = Samples()
    w.run(1.0)
    wait = FAST_BUS.reply_wait + FAST_BUS.tx_time(11)  # one probe, one try
    assert w.master.figures.cycle.max < wait + 0.002
    assert w.master.figures.cycle.median < 0.001


# ---------------------------------------------------------------------------------------
# retries and losses (1.1, 1.3, 1.5 step 7)


def test_a_lost_reply_is_repeated_with_the_same_fcb() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.run(0.01)
    w.clear()
    w.drop_replies = 1
    w.run(0.01)
    first, second = w.sent[0][1], w.sent[1][1]
    assert first == second  # 1.3: the retry keeps the FCB
    assert w.master.slave_figures(5).retries == 1
    assert w.line[5].counters.repeats == 1  # the slave saw the repeat and answered again
    assert all_in(w, 5)


def test_no_reply_after_the_retries_takes_the_slave_out_of_data_exchange() -> None:
    w = wire_for([5, 6])
    assert w.run_until(lambda: all_in(w, 5, 6), 1.0)
    w.line[5].faults.silent = True
    assert w.run_until(lambda: all_in(w, 5, state=SlaveState.ABSENT), 1.0)
    (down,) = w.of(SlaveDown)
    assert down.address == 5 and "no reply to Data_Exchange after 2 tries" in down.reason
    assert w.master.slave_figures(5).timeouts >= 2
    assert all_in(w, 6)
    w.line[5].faults.silent = False
    assert w.run_until(lambda: all_in(w, 5), 1.0)  # probed again, started again


def test_a_power_cycled_slave_comes_back_without_a_restart_of_the_master() -> None:
    w = wire_for([5, 6])
    assert w.run_until(lambda: all_in(w, 5, 6), 1.0)
    w.line[5].power_cycle(w.now, off_time=0.05)
    assert w.run_until(lambda: bool(w.of(SlaveDown)), 1.0)
    assert w.run_until(lambda: all_in(w, 5), 2.0)
    assert w.line[5].counters.power_cycles == 1
    assert len(w.of(SlaveUp)) == 3


def test_rs_means_the_slave_left_data_exchange() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.line[5].mode = SlaveMode.WAIT_PRM  # as after a watchdog expiry: Data_Exchange gets RS
    assert w.run_until(lambda: bool(w.of(SlaveDown)), 1.0)
    assert w.of(SlaveDown)[0].reason == "the slave left data exchange (RS)"
    assert w.run_until(lambda: all_in(w, 5), 1.0)


def test_a_late_reply_is_not_taken_for_the_next_one() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.late_by = FAST_BUS.reply_wait * 1.5
    w.run(0.05)
    assert w.master.figures.unexpected > 0
    w.late_by = 0.0
    w.run(0.5)
    assert all_in(w, 5)


def test_line_noise_costs_retries_not_the_exchange() -> None:
    w = wire_for([5, 6])
    assert w.run_until(lambda: all_in(w, 5, 6), 1.0)
    w.line.faults.bit_error_rate = 0.01
    w.clear()
    w.run(2.0)
    figures = w.master.figures
    assert figures.fcs_errors + figures.framing_errors > 0
    assert figures.retries > 0
    exchanges = [a.address for a in w.of(InputsReceived)]
    assert exchanges.count(5) > 100 and exchanges.count(6) > 100


# ---------------------------------------------------------------------------------------
# diagnosis (1.5 step 5-6, 1.8)


def test_dh_leads_to_a_diagnosis_read() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    device = w.line[5].device
    device.diag = bytes([3, 0x42, 0x07])  # type: ignore[attr-defined]
    assert w.run_until(lambda: any(d.ext for d in w.of(DiagnosisRead)), 0.1)
    ext = [d.ext for d in w.of(DiagnosisRead) if d.ext]
    assert ext[0] == bytes([3, 0x42, 0x07])
    reads = w.line[5].counters.diag_reads
    w.run(0.05)
    assert w.line[5].counters.diag_reads == reads  # read once, not every cycle
    assert all_in(w, 5)


@pytest.mark.parametrize("status", [ResponseStatus.DH, ResponseStatus.RDH])
def test_dh_and_rdh_replies_lead_to_a_diagnosis_read(status: ResponseStatus) -> None:
    """1.5 step 6: DH or RDH to Data_Exchange means a diagnosis waits; inputs still count."""
    s = _in_data_exchange()
    s.sent()  # Data_Exchange
    s.answer(_reply(status, bytes([9, 8, 7, 6])))
    assert s.of(InputsReceived)[-1] == InputsReceived(5, bytes([9, 8, 7, 6]))
    assert s.sent().dsap == 60  # Slave_Diag next, in the same turn
    s.answer(_diag_reply(SlaveDiag(0xEC00, ext_diag=True, master_address=2)))
    assert s.of(DiagnosisRead)[-1].address == 5
    assert s.sent().dsap is None  # back to Data_Exchange next cycle
    assert s.master.state_of(5) is DE


def test_a_diagnosis_answered_with_data_restarts_the_slave() -> None:
    s = _in_data_exchange()
    s.sent()  # Data_Exchange
    s.answer(_reply(ResponseStatus.DH, bytes(4)))
    assert s.sent().dsap == 60
    s.answer(_reply(ResponseStatus.DL, b""))  # an acknowledgement, no diagnosis
    assert s.of(SlaveDown)[-1].reason == "Slave_Diag answered with DL without SAP with 0 bytes"
    assert s.master.state_of(5) is SlaveState.WAIT_DIAG


def test_a_slave_that_keeps_asking_for_parameters_is_a_fault() -> None:
    w = wire_for([5])
    w.line[5].faults.prm_req_forever = True
    assert w.run_until(lambda: bool(w.of(SlaveFault)), 1.0)
    (fault,) = w.of(SlaveFault)
    assert fault.kind is FaultKind.PRM_REQ_LOOP
    assert fault.text == "the slave keeps asking for parameters (Prm_Req after 3 Set_Prm)"
    assert w.line[5].counters.set_prm == 3
    w.line[5].faults.prm_req_forever = False
    assert w.run_until(lambda: all_in(w, 5), 1.0)  # retried after fault_retry


def test_cfg_fault_is_reported_with_the_slaves_own_configuration() -> None:
    w = wire_for([5])
    w.line[5].faults.wrong_cfg = bytes([0xF3])
    assert w.run_until(lambda: bool(w.of(SlaveFault)), 1.0)
    (fault,) = w.of(SlaveFault)
    assert fault.kind is FaultKind.CFG_FAULT
    assert fault.text == (
        "Cfg_Fault: the slave refused the configuration B3 (4 bytes in, 4 bytes out); "
        "it has F3 (8 bytes in, 8 bytes out)"
    )
    w.run(1.0)
    assert len(w.of(SlaveFault)) == 1  # retried, but reported once


def test_prm_fault_names_the_ident_numbers() -> None:
    master = Master(FAST_BUS, [echo_params(5, ident_number=0x1234)])
    w = Wire(master, echo_line([5]))
    assert w.run_until(lambda: bool(w.of(SlaveFault)), 1.0)
    (fault,) = w.of(SlaveFault)
    assert fault.kind is FaultKind.PRM_FAULT
    assert fault.text == (
        "Prm_Fault: the slave refused the parameters (Ident_Number 0x1234, 0 bytes of user "
        "parameters); the slave reports Ident_Number 0xEC00"
    )
    assert master.fault_of(5) == fault.text


def test_prm_fault_from_the_device_itself() -> None:
    w = wire_for([5])
    w.line[5].device.accept_prm = False  # type: ignore[attr-defined]
    assert w.run_until(lambda: bool(w.of(SlaveFault)), 1.0)
    assert w.of(SlaveFault)[0].text == (
        "Prm_Fault: the slave refused the parameters (Ident_Number 0xEC00, 0 bytes of user "
        "parameters)"
    )


def test_prm_fault_in_the_slaves_own_words() -> None:
    """The slave's extended diagnosis goes into the fault text (1.8 device-related block)."""
    w = wire_for([5])
    device = w.line[5].device
    device.accept_prm = False  # type: ignore[attr-defined]
    device.diag = bytes([3, 0x1A, 0x00])  # type: ignore[attr-defined]
    assert w.run_until(lambda: bool(w.of(SlaveFault)), 1.0)
    (fault,) = w.of(SlaveFault)
    assert fault.kind is FaultKind.PRM_FAULT
    assert fault.text == (
        "Prm_Fault: the slave refused the parameters (Ident_Number 0xEC00, 0 bytes of user "
        "parameters); the slave's diagnosis: device diagnosis 1A 00"
    )


def test_cfg_fault_carries_the_slaves_diagnosis_too() -> None:
    w = wire_for([5])
    w.line[5].faults.wrong_cfg = bytes([0xF3])
    w.line[5].device.diag = bytes([0x81, 0x43, 0xA4])  # type: ignore[attr-defined]
    assert w.run_until(lambda: bool(w.of(SlaveFault)), 1.0)
    assert w.of(SlaveFault)[0].text.endswith(
        "it has F3 (8 bytes in, 8 bytes out); the slave's diagnosis: "
        "module 1 channel 3 (input, word): overload (error 4)"
    )


def _asking_for_parameters(master: Master) -> Script:
    """A scripted ``master``: slave 5 answered the first Slave_Diag with Prm_Req, the
    Set_Prm telegram is the next one out."""
    s = Script(master)
    s.sent()
    s.answer(_diag_reply(SlaveDiag(0xEC00, station_not_ready=True, prm_req=True)))
    return s


def _configured(master: Master) -> Script:
    """A scripted ``master``: slave 5 acknowledged Set_Prm and Chk_Cfg."""
    s = _asking_for_parameters(master)
    s.sent()
    s.answer(SHORT_ACK)
    s.sent()
    s.answer(SHORT_ACK)
    return s


def _in_data_exchange() -> Script:
    """A scripted master with slave 5 just in data exchange (the operate broadcast sent)."""
    s = _configured(Master(FAST_BUS, [echo_params(5)]))
    s.sent()
    s.answer(_diag_reply(SlaveDiag(0xEC00, master_address=2)))
    assert s.sent().dsap == 58  # operate broadcast
    return s


def test_prm_req_during_data_exchange_sends_set_prm_again() -> None:
    s = _configured(Master(FAST_BUS, [echo_params(5)]))
    s.sent()
    s.answer(_diag_reply(SlaveDiag(0xEC00, master_address=2)))
    s.sent()  # operate broadcast
    s.sent()  # Data_Exchange
    s.answer(_reply(ResponseStatus.DH, bytes(4)))  # DH: diagnosis waiting
    diag = s.sent()
    assert diag.dsap == 60
    s.answer(_diag_reply(SlaveDiag(0xEC00, prm_req=True, master_address=2)))
    assert s.sent().dsap == 61  # Set_Prm again (Prm_Req honoured)
    assert s.of(SlaveDown)[0].reason == "the slave asks for parameters (Prm_Req)"


def test_a_slave_locked_by_another_master_is_left_alone() -> None:
    master = Master(FAST_BUS, [echo_params(5)])
    s = Script(master)
    s.sent()
    s.answer(_diag_reply(SlaveDiag(0xEC00, master_address=7)))
    (fault,) = s.of(SlaveFault)
    assert fault.kind is FaultKind.LOCKED
    assert fault.text == "the slave is parameterised by master 7"
    assert master.state_of(5) is SlaveState.FAULT


def test_a_slave_that_stays_not_ready_times_out() -> None:
    master = Master(FAST_BUS, [echo_params(5)])
    s = _configured(master)
    for _ in range(5000):
        request = s.sent()
        if master.state_of(5) is SlaveState.FAULT:
            break
        if request.dsap == 60:
            s.answer(_diag_reply(SlaveDiag(0xEC00, station_not_ready=True, master_address=2)))
    (fault,) = s.of(SlaveFault)
    assert fault.kind is FaultKind.NOT_READY
    assert fault.text == "the slave stays not ready 1 s after Set_Prm and Chk_Cfg"


def test_set_prm_refused_at_fdl_level() -> None:
    s = _asking_for_parameters(Master(FAST_BUS, [echo_params(5)]))
    s.sent()
    s.answer(_reply(ResponseStatus.RS, b"", dsap=62, ssap=61))
    assert s.of(SlaveFault)[0].text == "the slave refused Set_Prm (RS from SAP 61 with 0 bytes)"


# ---------------------------------------------------------------------------------------
# DP-V1 (1.10)


def test_dpv1_write_then_read_back() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    job = w.master.write_record(5, 0, 1, b"\x12\x34", w.now)
    assert w.run_until(lambda: bool(w.of(RecordDone)), 0.1)
    assert w.of(RecordDone) == [RecordDone(job, 5, data=b"")]
    job = w.master.read_record(5, 0, 1, 240, w.now)
    assert w.run_until(lambda: len(w.of(RecordDone)) == 2, 0.1)
    assert w.of(RecordDone)[1] == RecordDone(job, 5, data=b"\x12\x34")


def test_dpv1_negative_answers_carry_the_slaves_codes() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.master.read_record(5, 0, 9, 4, w.now)  # no such index
    w.master.write_record(5, 0, 0, b"\x00", w.now)  # read-only
    w.master.read_record(5, 3, 1, 4, w.now)  # no such slot
    assert w.run_until(lambda: len(w.of(RecordDone)) == 3, 0.2)
    got = [(d.error.error_code_1, d.text) for d in w.of(RecordDone) if d.error]
    assert got == [
        (0xB0, "access error - invalid index"),
        (0xB6, "access error - access denied"),
        (0xB2, "access error - invalid slot"),
    ]


def test_dpv1_polls_until_the_answer_is_ready_without_starving_the_exchange() -> None:
    w = wire_for([5, 6])
    assert w.run_until(lambda: all_in(w, 5, 6), 1.0)
    w.line[5].faults.record_delay = 0.05
    w.clear()
    job = w.master.read_record(5, 0, 0, 4, w.now)
    assert w.run_until(lambda: bool(w.of(RecordDone)), 0.5)
    assert w.of(RecordDone)[0] == RecordDone(job, 5, data=b"\xec\x00\x01\x00")
    polls = [d for _, d in w.sent if len(d) == 11 and d[7] == 51 and d[8] == 51]
    assert len(polls) > 5  # 1.10: polled while the slave answers E5
    exchanges = [a.address for a in w.of(InputsReceived)]
    assert exchanges.count(5) >= len(polls) - 1  # every cycle still exchanged data
    assert exchanges.count(6) >= len(polls) - 1


def test_dpv1_jobs_are_served_in_order() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    jobs = [w.master.write_record(5, 0, 2, bytes([i]), w.now) for i in range(5)]
    last = w.master.read_record(5, 0, 2, 4, w.now)
    assert w.run_until(lambda: len(w.of(RecordDone)) == 6, 0.5)
    assert [d.job for d in w.of(RecordDone)] == [*jobs, last]
    assert w.of(RecordDone)[-1].data == bytes([4])


def test_dpv1_gives_up_after_the_acyclic_timeout() -> None:
    w = wire_for([5], acyclic_timeout=0.1)
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.line[5].faults.record_delay = 10.0
    start = w.now
    w.master.read_record(5, 0, 0, 4, w.now)
    assert w.run_until(lambda: bool(w.of(RecordDone)), 1.0)
    (done,) = w.of(RecordDone)
    assert done.failure is RecordFailure.TIMEOUT
    assert done.text == "no DP-V1 answer from slave 5 within 0.1 s"
    assert w.now - start == pytest.approx(0.1, abs=0.01)
    assert all_in(w, 5)


def test_dpv1_to_a_slave_out_of_data_exchange_fails_at_once() -> None:
    w = wire_for([5], configured=[5, 9])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.master.read_record(9, 0, 0, 4, w.now)
    w.poke()
    (done,) = w.of(RecordDone)
    assert done.failure is RecordFailure.OFFLINE
    assert done.text == "slave 9 not in data exchange"


def test_dpv1_jobs_fail_when_the_slave_leaves_data_exchange() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.line[5].faults.record_delay = 10.0
    w.master.read_record(5, 0, 0, 4, w.now)
    w.run(0.01)

    def poll_answered() -> bool:  # the turn is over: the next telegram is a Data_Exchange
        at, data = w.sent[-1]
        return data[:4] == bytes.fromhex("68 05 05 68") and w.received[-1][0] > at

    assert w.run_until(poll_answered, 1.0)
    w.line[5].faults.silent = True  # a Data_Exchange goes unanswered: the slave is gone
    assert w.run_until(lambda: bool(w.of(RecordDone)), 1.0)
    assert w.of(RecordDone)[0].failure is RecordFailure.OFFLINE


def test_a_cancelled_job_gives_no_answer() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.line[5].faults.record_delay = 0.02
    job = w.master.read_record(5, 0, 0, 4, w.now)
    w.run(0.005)
    w.master.cancel_record(job)
    w.run(0.1)
    assert w.of(RecordDone) == []


# ---------------------------------------------------------------------------------------
# Global_Control (1.9) and the live list


def test_clear_reaches_every_slave_and_operate_ends_it() -> None:
    w = wire_for([5, 6])
    assert w.run_until(lambda: all_in(w, 5, 6), 1.0)
    w.master.set_outputs(5, bytes([1, 2, 3, 4]))
    w.master.set_mode(LineMode.CLEAR, w.now)
    w.run(0.05)
    assert all(w.line[a].clear for a in (5, 6))
    assert w.line[5].last_outputs == bytes(4)  # zero outputs in Clear
    assert w.line[5].counters.comm_lost == 1
    w.master.set_mode(LineMode.OPERATE, w.now)
    w.run(0.05)
    assert not any(w.line[a].clear for a in (5, 6))
    assert w.line[5].last_outputs == bytes([1, 2, 3, 4])


def test_sync_and_freeze_reach_the_device() -> None:
    w = wire_for([5])
    assert w.run_until(lambda: all_in(w, 5), 1.0)
    w.master.global_control(GlobalControl(sync=True))
    w.run(0.01)
    assert w.line[5].sync
    seen = w.line[5].device.global_controls  # type: ignore[attr-defined]
    assert GlobalControl(sync=True) in seen


def test_the_live_list_probe_finds_other_stations() -> None:
    w = wire_for([5, 7, 40], configured=[5], live_list_period=0.001)
    w.run(0.5)
    assert w.master.live_list() == [5, 7, 40]


# ---------------------------------------------------------------------------------------
# helpers


def _reply(
    status: ResponseStatus, data: bytes, dsap: int | None = None, ssap: int | None = None
) -> DataTelegram:
    return DataTelegram(2, 5, ResponseFc(status), dsap, ssap, data)


def _diag_reply(diag: SlaveDiag) -> DataTelegram:
    return _reply(ResponseStatus.DL, diag.encode(), 62, 60)
