"""Engine-level properties (hypothesis): whatever the line does, the master keeps the rules.

* 1.1: one request at a time, and at least TSYN of idle line before each;
* 1.3: a repeat keeps the FCB, a new request toggles it, a (re)start sends FCB=1 FCV=0;
* 1.5: every slave that answers reaches data exchange; one that never answers never does,
  and neither stalls the others;
* nothing the line delivers (any telegram, any garbage) makes the engine raise.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import partial
from typing import Any

from hypothesis import example, given, settings
from hypothesis import strategies as st

from adapters.profibus.codec.dp import GlobalControl
from adapters.profibus.codec.fdl import (
    DataTelegram,
    RequestFc,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    ShortAck,
    StationType,
    decode_fc,
    decode_telegram,
)
from adapters.profibus.errors import DecodeFailure, FdlDecodeError
from adapters.profibus.master import (
    FrameIn,
    InputsReceived,
    LineMode,
    LineNoise,
    Master,
    Receiving,
    SlaveState,
    SlaveUp,
    Transmit,
)
from adapters.profibus.sim.echo import EchoSim
from adapters.profibus.sim.slave import DpSlave
from gateway.sim import FaultInjector
from tests.profibus.wire import FAST_BUS, Wire, echo_line, echo_params

FAST = settings(max_examples=15, deadline=None)
ADDRESSES = st.lists(st.integers(3, 12), min_size=1, max_size=5, unique=True)


def check_line_rules(w: Wire) -> None:
    bus = w.master.bus
    for (t0, d0), (t1, _) in zip(w.sent, w.sent[1:], strict=False):
        assert t1 >= t0 + bus.tx_time(len(d0)) + bus.tsyn - 1e-9  # 1.1: TSYN before each
    last: dict[int, bytes] = {}
    for _, data in w.sent:
        telegram = decode_telegram(data)
        assert isinstance(telegram, DataTelegram)
        fc = telegram.fc
        assert isinstance(fc, RequestFc)
        if fc.function is not RequestFunction.SRD_HIGH:
            continue
        previous = last.get(telegram.da)
        if not fc.fcv:
            assert fc.fcb  # 1.3: after a (re)start FCB = 1, FCV = 0
        elif previous is not None and previous != data:
            before = decode_fc(previous[6] if previous[0] == 0x68 else previous[3])
            assert isinstance(before, RequestFc)
            assert before.fcb != fc.fcb  # 1.3: toggled after each acknowledged request
        last[telegram.da] = data


@FAST
@given(present=ADDRESSES, absent=ADDRESSES, drop=st.floats(0.0, 0.3), seed=st.integers(0, 99))
def test_present_slaves_reach_data_exchange_whatever_is_lost(
    present: list[int], absent: list[int], drop: float, seed: int
) -> None:
    missing = [a for a in absent if a not in present]
    master = Master(FAST_BUS, [echo_params(a) for a in present + missing])
    line = echo_line(present)
    line.faults = FaultInjector(seed=seed, drop_rate=drop)
    w = Wire(master, line)
    w.run(1.5)
    up = {a.address for a in w.of(SlaveUp)}
    assert up == set(present)
    for a in missing:
        assert master.state_of(a) is SlaveState.ABSENT
    check_line_rules(w)


@FAST
@given(noise=st.floats(0.0, 0.02), seed=st.integers(0, 99))
# a garbled reply seen while the next request was still going out: that request's end,
# not the reply, starts the idle time before the one after it (found by this test)
@example(noise=0.02, seed=39)
# a slave absent at start: up after a few probes, later than the first second
@example(noise=0.019266597500388397, seed=64)
def test_line_rules_hold_under_noise(noise: float, seed: int) -> None:
    master = Master(FAST_BUS, [echo_params(a) for a in (5, 6, 7)])
    line = echo_line([5, 6, 7])
    line.faults = FaultInjector(seed=seed, bit_error_rate=noise)
    w = Wire(master, line)
    # Up to 2 % of the bytes garbled: a slave can go absent at start (every try lost) and
    # is then probed every absent_retry (0.2 s), so it may take a few seconds of line time.
    w.run_until(lambda: {a.address for a in w.of(SlaveUp)} == {5, 6, 7}, 10.0)
    check_line_rules(w)
    assert {a.address for a in w.of(SlaveUp)} == {5, 6, 7}


responses = st.builds(
    DataTelegram,
    da=st.sampled_from([2, 2, 2, 3]),
    sa=st.integers(0, 12),
    fc=st.builds(ResponseFc, st.sampled_from(ResponseStatus), st.sampled_from(StationType)),
    dsap=st.one_of(st.none(), st.integers(0, 63)),
    ssap=st.one_of(st.none(), st.sampled_from([51, 59, 60, 61, 62]), st.integers(0, 63)),
    data=st.binary(max_size=40),
)
events = st.one_of(
    responses.map(FrameIn),
    st.just(FrameIn(ShortAck())),
    st.builds(
        lambda raw: LineNoise(FdlDecodeError(DecodeFailure.BAD_CHECKSUM, "noise", raw)),
        st.binary(min_size=1, max_size=8),
    ),
    st.just(Receiving()),
    st.builds(
        lambda sa: FrameIn(DataTelegram(5, 2, RequestFc(RequestFunction.SRD_HIGH), data=b"x")),
        st.just(0),
    ),
)


@settings(max_examples=60, deadline=None)
@given(script=st.lists(st.tuples(st.floats(0.0, 0.01), events), max_size=80))
def test_nothing_from_the_line_makes_the_engine_raise(script: list[tuple[float, object]]) -> None:
    bus = dataclasses.replace(FAST_BUS, live_list_period=0.001)
    master = Master(bus, [echo_params(a) for a in (3, 5, 7)])
    master.read_record(5, 0, 1, 4, 0.0)
    now = 0.0
    master.step(now)
    for dt, event in script:
        now += dt
        actions = master.step(now, event)  # type: ignore[arg-type]
        assert sum(1 for a in actions if isinstance(a, Transmit) and a.expect_reply) <= 1
        deadline = master.next_deadline()
        assert deadline is None or deadline > now  # never a busy loop
    assert master.figures.telegrams >= 1


requests = st.builds(
    DataTelegram,
    da=st.sampled_from([5, 5, 127, 6]),
    sa=st.sampled_from([2, 3]),
    fc=st.builds(RequestFc, st.sampled_from(RequestFunction), st.booleans(), st.booleans()),
    dsap=st.one_of(st.none(), st.sampled_from([50, 51, 55, 56, 57, 58, 59, 60, 61, 62])),
    ssap=st.one_of(st.none(), st.sampled_from([51, 62])),
    data=st.binary(max_size=30),
)


@settings(max_examples=100, deadline=None)
@given(script=st.lists(requests, max_size=40))
def test_nothing_from_a_master_makes_the_simulated_slave_raise(script: list[DataTelegram]) -> None:
    from adapters.profibus.sim.echo import EchoSim

    slave = DpSlave(5, EchoSim())
    for i, request in enumerate(script):
        reply = slave.handle(request, i * 0.01)
        if reply is not None:
            reply.encode()
        slave.tick(i * 0.01)


# --------------------------------------------------------------------------- the short path


class GeneralPathOnly(Master):
    """The engine without its short path for the steady case of data exchange."""

    def _steady_reply(self, t: object, now: float, raw: bytes = b"") -> bool:
        return False


Command = tuple[str, int]
commands: st.SearchStrategy[Command] = st.tuples(
    st.sampled_from(
        [
            "read",
            "write",
            "clear",
            "operate",
            "sync",
            "power",
            "diag",
            "static",
            "slowstart",
            "drop",
        ]
    ),
    st.integers(0, 3),
)
EXT_DIAG = bytes([0x03, 0x01, 0x02])  # a device-related block of 3 bytes, header included


def _slow_start(w: Wire, address: int) -> None:
    """The slave restarts and stays not ready (its application does not come up)."""
    w.line[address].faults.not_ready = True
    w.line[address].power_cycle(w.now, off_time=0.01)


def _apply(w: Wire, addresses: list[int], command: Command) -> None:
    what, n = command
    address = addresses[n % len(addresses)]
    device = w.line[address].device
    faults = w.line[address].faults
    assert isinstance(device, EchoSim)
    actions: dict[str, Callable[[], object]] = {
        "read": lambda: w.master.read_record(address, 0, 1 + n, 4, w.now),
        "write": lambda: w.master.write_record(address, 0, 1, bytes([n] * 4), w.now),
        "clear": lambda: w.master.set_mode(LineMode.CLEAR, w.now),
        "operate": lambda: w.master.set_mode(LineMode.OPERATE, w.now),
        "sync": lambda: w.master.global_control(GlobalControl(sync=True)),
        "power": lambda: w.line[address].power_cycle(w.now, off_time=0.01),
        "diag": lambda: setattr(device, "diag", b"" if device.diag else EXT_DIAG),
        "static": lambda: setattr(faults, "stat_diag", not faults.stat_diag),
        "slowstart": lambda: _slow_start(w, address),
        "drop": lambda: setattr(w, "drop_replies", n),
    }
    actions[what]()
    w.poke()


def _trace(
    engine: type[Master],
    *,
    addresses: list[int],
    noise: float,
    seed: int,
    script: list[tuple[float, Command]],
    probe: float,
) -> tuple[list[tuple[float, bytes]], list[Any], dict[str, Any], list[dict[str, Any]]]:
    bus = dataclasses.replace(FAST_BUS, live_list_period=probe)
    master = engine(bus, [echo_params(a) for a in addresses])
    line = echo_line(addresses)
    line.faults = FaultInjector(seed=seed, bit_error_rate=noise)
    w = Wire(master, line)

    def adapter(action: object) -> None:  # new outputs from every reply's inputs
        if isinstance(action, InputsReceived):
            master.set_outputs(action.address, bytes((b + 1) % 256 for b in action.data))

    w.on_action = adapter
    w.run(0.2)
    for wait, command in script:
        w.run(wait)
        _apply(w, addresses, command)
    w.run(2.0)  # past the start-up states' timeouts (a slave left not ready, 1 s)
    slaves = [master.slave_diagnostics(a) for a in addresses]
    return w.sent, w.actions, master.line_diagnostics(), slaves


@settings(max_examples=30, deadline=None)
@given(
    addresses=st.lists(st.integers(3, 9), min_size=1, max_size=4, unique=True),
    noise=st.sampled_from([0.0, 0.0, 1e-3, 1e-2]),
    seed=st.integers(0, 99),
    script=st.lists(st.tuples(st.floats(0.001, 0.03), commands), max_size=10),
    probe=st.sampled_from([0.0, 0.005]),  # live-list probes off, or one every 5 ms
)
def test_the_short_path_sends_and_reports_what_the_general_path_does(
    addresses: list[int],
    noise: float,
    seed: int,
    script: list[tuple[float, Command]],
    probe: float,
) -> None:
    trace = partial(_trace, addresses=addresses, noise=noise, seed=seed, script=script, probe=probe)
    short, general = trace(Master), trace(GeneralPathOnly)
    assert short == general
    assert len(short[0]) > 50  # telegrams went out: the comparison compared something


def _job_between_reply_and_tsyn(engine: type[Master]) -> tuple[list[tuple[float, bytes]], Any]:
    """A DP-V1 read given while a steady reply's TSYN runs (the adapter's handling of the
    inputs, before the next request is decided)."""
    master = engine(FAST_BUS, [echo_params(3), echo_params(4)])
    w = Wire(master, echo_line([3, 4]))
    asked: list[int] = []

    def adapter(action: object) -> None:
        in_exchange = all(master.state_of(a) is SlaveState.DATA_EXCHANGE for a in (3, 4))
        if isinstance(action, InputsReceived) and in_exchange and not asked:
            asked.append(master.read_record(action.address, 0, 1, 4, w.now))

    w.on_action = adapter
    w.run(0.2)
    assert asked
    return w.sent, [a for a in w.actions if not isinstance(a, InputsReceived)]


def test_a_job_given_during_a_steady_replys_tsyn_goes_the_general_way() -> None:
    """The short path taken at the TSYN deadline after a steady reply defers to the general
    path when a DP-V1 job came meanwhile: the job's request follows in the same turn."""
    assert _job_between_reply_and_tsyn(Master) == _job_between_reply_and_tsyn(GeneralPathOnly)
