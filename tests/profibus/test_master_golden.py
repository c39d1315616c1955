"""Engine-level golden sequences: the master's telegrams byte for byte (fact sheet 1.2-1.10).

Master 2, slave 5. The fact sheet's example frames (1.2 first Slave_Diag, Data_Exchange with
4 output bytes; 1.6 Set_Prm with lock, watchdog 100 ms, ident 0x80B5; 1.9 Global_Control;
1.10 DP-V1 read of index 47; 1.2 FDL status request) must come out of the engine exactly,
at the place the start-up sequence (1.5) and the FCB rules (1.3) put them. The replies are
what a slave sends, written out (a 6-byte diagnosis is an SD3 telegram: LE 11).
"""

from __future__ import annotations

import pytest

from adapters.profibus.codec.dp import GlobalControl
from adapters.profibus.codec.fdl import SHORT_ACK
from adapters.profibus.master import (
    InputsReceived,
    LineMode,
    Master,
    RecordDone,
    SlaveParams,
    SlaveState,
    SlaveUp,
)
from adapters.profibus.master.scan import Scanner, SlaveInfo, status_request
from adapters.profibus.master.timing import BusParams
from tests.profibus.script import Script, h

BUS = BusParams.for_baudrate(500000, latency=0.001)

FIRST_DIAG = "68 05 05 68 85 82 6D 3C 3E EE 16"  # 1.2 example
SET_PRM = "68 0F 0F 68 85 82 5D 3D 3E 88 01 0A 0B 80 B5 00 00 00 00 B2 16"  # 1.6 example
CHK_CFG = "68 06 06 68 85 82 7D 3E 3E F1 F1 16"  # 0xF1: 2 words in + out (1.7)
SECOND_DIAG = "68 05 05 68 85 82 5D 3C 3E DE 16"
OPERATE = "68 07 07 68 FF 82 46 3A 3E 00 00 3F 16"  # 1.9 example
CLEAR = "68 07 07 68 FF 82 46 3A 3E 02 00 41 16"
DATA_1 = "68 07 07 68 05 02 7D 04 7F 20 00 27 16"
DATA_2 = "68 07 07 68 05 02 5D 04 7F 20 00 07 16"  # 1.2 example
READ_47 = "68 09 09 68 85 82 7D 33 33 5E 00 2F F0 67 16"  # 1.10 example
POLL = "68 05 05 68 85 82 5D 33 33 CA 16"

# replies of slave 5
DIAG_FRESH = "A2 82 85 08 3E 3C 02 05 00 FF 80 B5 C4 16"  # Not_Ready, Prm_Req, no master
DIAG_READY = "A2 82 85 08 3E 3C 00 0C 00 02 80 B5 CC 16"  # WD_On, Master_Add 2
INPUTS = "68 07 07 68 02 05 08 11 22 33 44 B9 16"
READ_ANSWER = "68 0D 0D 68 82 85 08 33 33 5E 00 2F 04 01 02 03 04 10 16"
READ_ERROR = "68 09 09 68 82 85 08 33 33 DE 80 B0 00 83 16"


def slave(dpv1: bool = False) -> SlaveParams:
    return SlaveParams(
        address=5,
        ident_number=0x80B5,
        cfg=h("F1"),
        user_prm=b"" if dpv1 else h("00 00 00"),  # 1.6 example: 00 00 00 after byte 6
        input_len=4,
        output_len=4,
        dpv1=dpv1,
        watchdog=0.1,
    )


def start(script: Script, set_prm: str | None = SET_PRM) -> None:
    script.sent(FIRST_DIAG)
    script.answer(DIAG_FRESH)
    script.sent(set_prm)
    script.answer(SHORT_ACK)
    script.sent(CHK_CFG)
    script.answer(SHORT_ACK)
    script.sent(SECOND_DIAG)
    script.answer(DIAG_READY)
    assert script.of(SlaveUp) == [SlaveUp(5)]
    script.sent(OPERATE)  # end of the first cycle: the line task (1.9)


def test_start_up_and_data_exchange_byte_for_byte() -> None:
    master = Master(BUS, [slave()])
    script = Script(master)
    start(script)
    master.set_outputs(5, h("04 7F 20 00"))
    script.sent(DATA_1)
    script.answer(INPUTS)
    script.sent(DATA_2)
    script.answer(INPUTS)
    assert script.of(InputsReceived)[-1] == InputsReceived(5, h("11 22 33 44"))
    assert master.state_of(5) is SlaveState.DATA_EXCHANGE


def test_dpv1_read_of_index_47_request_poll_and_answer() -> None:
    master = Master(BUS, [slave(dpv1=True)])
    script = Script(master)
    dpv1_set_prm = "68 0F 0F 68 85 82 5D 3D 3E 88 01 0A 0B 80 B5 00 80 00 00 32 16"
    start(script, dpv1_set_prm)
    master.set_outputs(5, h("04 7F 20 00"))
    script.sent(DATA_1)
    script.answer(INPUTS)
    script.sent(DATA_2)
    job = master.read_record(5, 0, 47, 240, script.now)  # taken in this turn
    script.answer(INPUTS)
    script.sent(READ_47)
    script.answer(SHORT_ACK)  # 1.10: the request is taken, the answer comes on a poll
    script.sent(POLL)
    script.answer(READ_ANSWER)
    assert script.of(RecordDone) == [RecordDone(job, 5, data=h("01 02 03 04"))]


def test_dpv1_error_answer_carries_the_codes() -> None:
    master = Master(BUS, [slave(dpv1=True)])
    script = Script(master)
    start(script, "68 0F 0F 68 85 82 5D 3D 3E 88 01 0A 0B 80 B5 00 80 00 00 32 16")
    script.sent("68 07 07 68 05 02 7D 00 00 00 00 84 16")  # outputs never set: zeros
    script.answer(INPUTS)
    script.sent()
    job = master.read_record(5, 0, 47, 240, script.now)  # taken in this turn
    script.answer(INPUTS)
    script.sent(READ_47)
    script.answer(READ_ERROR)  # answered at once (DL with the error PDU)
    (done,) = script.of(RecordDone)
    assert done.job == job and done.error is not None
    assert (done.error.error_decode, done.error.error_code_1) == (0x80, 0xB0)
    assert done.text == "access error - invalid index"


def test_leave_sends_global_control_clear_twice() -> None:
    master = Master(BUS, [slave()])
    script = Script(master)
    start(script)
    out = master.leave(script.now)
    assert [t.data for t in out] == [h(CLEAR), h(CLEAR)]
    assert not any(t.expect_reply for t in out)
    gap = out[1].not_before - out[0].not_before
    assert gap == pytest.approx(BUS.tx_time(13) + BUS.tsyn)  # one after the other, TSYN between
    assert master.step(script.now + 1) == []  # left: nothing more


def test_clear_mode_broadcasts_clear_and_sends_zero_outputs() -> None:
    master = Master(BUS, [slave()])
    script = Script(master)
    start(script)
    master.set_outputs(5, h("04 7F 20 00"))
    master.set_mode(LineMode.CLEAR, script.now)
    script.sent(CLEAR)  # at the end of the cycle under way
    script.sent("68 07 07 68 05 02 7D 00 00 00 00 84 16")  # 1.5 step 6: Clear: all zero
    script.answer(INPUTS)


def test_sync_and_freeze_go_out_after_the_slaves() -> None:
    master = Master(BUS, [slave()])
    script = Script(master)
    start(script)
    master.global_control(GlobalControl(sync=True, freeze=True, group_select=1))
    script.sent("68 07 07 68 FF 82 46 3A 3E 28 01 68 16")  # b5 Sync, b3 Freeze, group 1
    script.sent(DATA_1.replace("04 7F 20 00 27", "00 00 00 00 84"))  # the next cycle


def test_fdl_status_request_of_the_scan() -> None:
    assert status_request(5, 2) == h("10 05 02 49 50 16")  # 1.2 example
    scanner = Scanner(BUS, [5], identify=False)
    script = Script(scanner)  # type: ignore[arg-type]
    script.sent("10 05 02 49 50 16")
    script.answer("10 02 05 00 07 16")  # FC 00: a slave, OK
    assert scanner.done and set(scanner.found) == {5}


def test_the_scan_reads_a_slaves_ident_number_and_configuration() -> None:
    scanner = Scanner(BUS, [5])
    script = Script(scanner)  # type: ignore[arg-type]
    script.sent("10 05 02 49 50 16")
    script.answer("10 02 05 00 07 16")  # a slave
    script.sent(FIRST_DIAG)  # 1.8: Slave_Diag, read-only
    script.answer(DIAG_FRESH)  # Ident_Number 0x80B5, no master (FF)
    script.sent("68 05 05 68 85 82 6D 3B 3E ED 16")  # 1.7: Get_Cfg to SAP 59
    script.answer("68 06 06 68 82 85 08 3E 3B F1 79 16")  # F1
    assert scanner.done and scanner.probed == 1
    assert scanner.slaves[5] == SlaveInfo(0x80B5, 0xFF, b"\xf1")
