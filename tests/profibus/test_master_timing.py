"""The master's timing under a late event loop (fact sheet 1.1, 1.10; issue 18).

The engine is stepped with an injected clock; the driver's late callbacks are injected as
``Written`` events carrying the time the bytes really went (``Script.write_lag``,
``Wire.write_lag``). Every idle time (TSYN) and reply deadline must count from there, and
any byte received restarts the idle time.
"""

from __future__ import annotations

import dataclasses

from adapters.profibus.codec.fdl import SHORT_ACK
from adapters.profibus.master import (
    FaultKind,
    InputsReceived,
    Master,
    RecordDone,
    RecordFailure,
    SlaveDown,
    SlaveFault,
    SlaveState,
    Transmit,
)
from adapters.profibus.master.timing import BusParams
from tests.profibus.script import Script
from tests.profibus.test_master_golden import (
    CHK_CFG,
    DIAG_FRESH,
    DIAG_READY,
    FIRST_DIAG,
    INPUTS,
    OPERATE,
    SECOND_DIAG,
    SET_PRM,
    slave,
)
from tests.profibus.wire import FAST_BUS, Wire, echo_line, echo_params

SLOW = BusParams.for_baudrate(19200)  # the line: TSYN 1.72 ms, reply wait ~15 ms
FAST = BusParams.for_baudrate(500000, latency=0.001)  # TSYN 66 us
LATE = 0.005  # s: how late a loop callback writes
EPS = 1e-9  # s: float rounding of the sums


def to_data_exchange(script: Script, *, operate_lag: float = 0.0) -> None:
    """The golden start-up (1.5), the Operate broadcast written ``operate_lag`` late."""
    script.sent(FIRST_DIAG)
    script.answer(DIAG_FRESH)
    script.sent(SET_PRM)
    script.answer(SHORT_ACK)
    script.sent(CHK_CFG)
    script.answer(SHORT_ACK)
    script.sent(SECOND_DIAG)
    script.answer(DIAG_READY)
    script.write_lag = operate_lag
    script.sent(OPERATE)
    script.write_lag = 0.0


def test_the_request_after_a_late_broadcast_waits_its_line_time_and_tsyn() -> None:
    """18 of 54 requests after Global_Control came 7.5 ms after it at 19.2 kbit/s, against
    9.17 ms: the idle time counted from the broadcast's planned time."""
    script = Script(Master(SLOW, [slave()]))
    to_data_exchange(script, operate_lag=LATE)
    operate_written = script.written[-1]
    script.sent()  # the first Data_Exchange
    gap = script.transmits[-1].not_before - operate_written
    assert gap >= SLOW.tx_time(13) + SLOW.tsyn - EPS  # 13 bytes of Operate, then 33 bit times


def test_a_stray_reply_restarts_the_idle_time() -> None:
    """A slave answers a request and its retry: the second answer comes after the master
    took the first, and the next request still waits TSYN after it (not 46 us)."""
    script = Script(Master(FAST, [slave()]))
    to_data_exchange(script)
    script.sent()  # Data_Exchange
    script.silence()  # its reply is late: the retry goes out
    script.sent()  # the retry
    sent = len(script.transmits)
    script.answer(INPUTS)  # the late answer to the first try, taken
    script.answer(INPUTS, after=20e-6)  # the answer to the retry: a stray reply
    stray = script.now
    script.sent()
    assert script.transmits[sent].not_before >= stray + FAST.tsyn - EPS
    assert script.master.figures.unexpected == 1


def test_a_retry_waits_the_reply_time_after_the_late_first_try() -> None:
    """A retry came 4.5 ms after the first try at 19.2 kbit/s where the wait is ~21 ms:
    the reply deadline counted from the planned time, not from the late write."""
    script = Script(Master(SLOW, [slave()]))
    to_data_exchange(script)
    script.write_lag = 3 * LATE  # the first try goes out 15 ms late
    script.sent()
    script.write_lag = 0.0
    first = script.written[-1]
    script.silence()
    script.sent()  # the retry
    assert script.written[-1] - first >= SLOW.tx_time(13) + SLOW.reply_wait - EPS


def test_nothing_goes_out_or_times_out_before_the_write_is_confirmed() -> None:
    """The driver's write is late: until ``Written`` the engine sends nothing more and does
    not judge the reply deadline, whatever the clock says."""
    master = Master(FAST, [slave()])
    script = Script(master)
    to_data_exchange(script)
    now, out = script.now, []
    for _ in range(100):  # step until the next request is handed to the driver
        out = [a for a in master.step(now) if isinstance(a, Transmit)]
        deadline = master.next_deadline()
        if out or deadline is None:
            break
        now = max(now, deadline)
    assert out  # a Data_Exchange, not confirmed written
    assert master.next_deadline() is None
    assert master.step(now + 10.0) == []  # no timeout, no second request
    assert master.state_of(5) is SlaveState.DATA_EXCHANGE


def test_a_late_write_everywhere_keeps_every_gap_and_every_slave() -> None:
    """Every write 2 ms late on a 500 kbit/s line for 2 s: no request starts sooner than
    TSYN after the line's last activity (written or received) and nobody leaves data
    exchange."""
    master = Master(FAST_BUS, [echo_params(a) for a in (5, 6, 7)])
    w = Wire(master, echo_line([5, 6, 7]))
    w.write_lag = 0.002
    assert w.run_until(
        lambda: all(master.state_of(a) is SlaveState.DATA_EXCHANGE for a in (5, 6, 7))
    )
    w.clear()
    w.run(2.0)
    assert not w.of(SlaveDown)
    ends = sorted([t + FAST_BUS.tx_time(len(d)) for t, d in w.sent] + [t for t, _ in w.received])
    for start, _ in w.sent:
        before = [e for e in ends if e <= start]
        if before:
            assert start - before[-1] >= FAST_BUS.tsyn - EPS
    assert master.figures.retries == 0 and len(w.of(InputsReceived)) > 300


def _dpv1_wire() -> Wire:
    bus = dataclasses.replace(FAST_BUS, acyclic_timeout=0.5)
    master = Master(bus, [echo_params(5, dpv1=True)])
    return Wire(master, echo_line([5]))


def test_an_unanswered_dpv1_request_keeps_data_exchange_and_backs_off() -> None:
    """MSAC_C1 left unanswered made the master restart the slave ~8 times a second: now
    the job fails, the slave stays in data exchange, DP-V1 backs off, one fault event."""
    w = _dpv1_wire()
    master = w.master
    assert w.run_until(lambda: master.state_of(5) is SlaveState.DATA_EXCHANGE, 1.0)
    w.line[5].faults.dpv1_silent = True
    w.clear()
    jobs = 0

    def again(action: object) -> None:  # a caller that asks again at once, as on_connect
        nonlocal jobs
        if isinstance(action, RecordDone):
            jobs += 1
            master.read_record(5, 0, 1, 4, w.now)

    w.on_action = again
    master.read_record(5, 0, 1, 4, w.now)
    w.run(4.0)
    assert not w.of(SlaveDown) and master.state_of(5) is SlaveState.DATA_EXCHANGE
    assert master.slave_figures(5).restarts == 0
    faults = w.of(SlaveFault)
    assert [f.kind for f in faults] == [FaultKind.DPV1_UNANSWERED]  # once
    assert "unanswered" in faults[0].text and "data exchange goes on" in faults[0].text
    done = w.of(RecordDone)
    assert done and all(d.failure is RecordFailure.TIMEOUT for d in done)
    # held 1 s, then 2 s: three series of tries in 4 s, not a restart every 125 ms
    dpv1_sent = [d for _, d in w.sent if d[0] == 0x68 and d[7] == 0x33]
    assert 2 <= len(dpv1_sent) <= 3 * (1 + FAST_BUS.retries)
    assert len(w.of(InputsReceived)) > 1000  # DP-V0 went on all along


def test_dpv1_answered_again_ends_the_hold_and_a_new_silence_is_reported_again() -> None:
    w = _dpv1_wire()
    master = w.master
    assert w.run_until(lambda: master.state_of(5) is SlaveState.DATA_EXCHANGE, 1.0)
    w.line[5].faults.dpv1_silent = True
    master.read_record(5, 0, 1, 4, w.now)
    assert w.run_until(lambda: bool(w.of(RecordDone)), 1.0)
    held = master.read_record(5, 0, 1, 4, w.now)  # refused at once while held
    w.poke()
    assert w.of(RecordDone)[-1].job == held and "held" in w.of(RecordDone)[-1].text
    w.line[5].faults.dpv1_silent = False
    w.run(1.1)  # the hold is over
    ok = master.read_record(5, 0, 1, 4, w.now)
    assert w.run_until(lambda: w.of(RecordDone)[-1].job == ok, 1.0)
    assert w.of(RecordDone)[-1].failure is None
    w.line[5].faults.dpv1_silent = True
    master.read_record(5, 0, 1, 4, w.now)
    assert w.run_until(lambda: len(w.of(SlaveFault)) == 2, 1.0)
