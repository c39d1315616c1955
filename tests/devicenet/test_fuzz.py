"""Every DeviceNet decoder on random frames: random 11-bit ids, 0-8 random bytes.

Whatever the input, only DeviceNetDecodeError subclasses (FrameDecodeError) escape; and
the scanner engine and the simulated CFW-08, online, take random frames on their own
identifiers without an exception (bad input is counted, never fatal).
"""

from __future__ import annotations

from collections.abc import Callable

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.cfw08 import INPUT_DECODERS, OUTPUT_DECODERS, decode_parameter
from adapters.devicenet.cfw08.objects import Kind, decode_attribute
from adapters.devicenet.codec.datatypes import CipType, decode_short_string, decode_value
from adapters.devicenet.codec.dupmac import DupMacCheck
from adapters.devicenet.codec.explicit import BodyFormat, ExplicitMessage
from adapters.devicenet.codec.fragment import (
    ExplicitFragment,
    ExplicitReassembler,
    IoFragment,
    IoReassembler,
    decode_explicit_frame,
)
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import decode_can_id, match_predefined
from adapters.devicenet.codec.objects import AllocationInfo
from adapters.devicenet.errors import DeviceNetDecodeError
from adapters.devicenet.scanner import FrameIn, IoKind, NodeConfig
from adapters.devicenet.sim.node import SimNodeConfig
from adapters.link.canerror import decode_error_frame
from gateway.errors import FrameDecodeError
from tests.devicenet.harness import Line
from tests.devicenet.strategies import frames
from tests.devicenet.test_scanner import FAST


def _explicit_via_reassembler(receiver: ExplicitReassembler, frame: CanFrame) -> object:
    sorted_frame = decode_explicit_frame(frame.data)
    if isinstance(sorted_frame, ExplicitFragment):
        step = receiver.feed(0.0, sorted_frame)
        if step.message is not None:
            return ExplicitMessage.decode(step.message)
    return sorted_frame


def _decoders(
    explicit: ExplicitReassembler, io: IoReassembler
) -> list[Callable[[CanFrame], object]]:
    return [
        lambda f: CanFrame.from_bus(f.arbitration_id, f.data),
        lambda f: decode_can_id(f.arbitration_id),
        lambda f: match_predefined(f.arbitration_id),
        DupMacCheck.from_frame,
        *(
            (
                lambda f, fmt=fmt: ExplicitMessage.decode(
                    f.data, fmt, arbitration_id=f.arbitration_id
                )
            )
            for fmt in BodyFormat
        ),
        lambda f: decode_explicit_frame(f.data),
        lambda f: IoFragment.decode(f.data),
        lambda f: _explicit_via_reassembler(explicit, f),
        lambda f: io.feed(0.0, f.data),
        lambda f: decode_value(CipType.UINT, f.data),
        lambda f: decode_short_string(f.data),
        lambda f: AllocationInfo.decode(f.data),
        lambda f: decode_parameter(f.data),
        lambda f: decode_error_frame(f.arbitration_id, f.data),
        *(
            (lambda f, d=d: d(f.data))
            for d in (*INPUT_DECODERS.values(), *OUTPUT_DECODERS.values())
        ),
        *((lambda f, k=k: decode_attribute(k, f.data)) for k in Kind),
    ]


@settings(max_examples=400, deadline=None)
@given(st.lists(frames, min_size=1, max_size=6))
def test_every_decoder_raises_only_typed_errors(batch):
    decoders = _decoders(ExplicitReassembler(), IoReassembler())
    for frame in batch:
        for decode in decoders:
            try:
                decode(frame)
            except DeviceNetDecodeError as exc:
                assert isinstance(exc, FrameDecodeError)
                assert isinstance(exc, ValueError)


# ---------------------------------------------------------------- the stacks themselves

NODE = 2
# Every identifier of the predefined set that carries MAC 2, and the scanner's DupMAC id.
NODE_IDS = (
    [(g << 6) | NODE for g in (0xC, 0xD, 0xE, 0xF)]
    + [0x400 | NODE << 3 | m for m in range(8)]
    + [0x407]
)
scanner_frames = st.builds(
    CanFrame,
    st.sampled_from(NODE_IDS),
    st.one_of(
        st.binary(max_size=8),
        # explicit traffic addressed to the scanner (MAC 0), fragments included
        st.tuples(st.sampled_from([0x00, 0x40, 0x80, 0xC0]), st.binary(max_size=7)).map(
            lambda t: bytes((t[0],)) + t[1]
        ),
    ),
)


@settings(max_examples=60, deadline=None)
@given(
    st.sampled_from([IoKind.POLLED, IoKind.COS]),
    st.sampled_from([0.02, 0.12, 0.3]),
    st.lists(st.tuples(scanner_frames, st.floats(0.0, 0.05)), max_size=25),
)
def test_the_scanner_and_the_simulated_drive_take_random_frames(io, settle, batch):
    lin = Line(
        FAST, [NodeConfig(NODE, io=io, epr=0.05)], [SimNodeConfig(NODE, dupmac_timeout=0.05)]
    )
    lin.power_on()
    lin.run(settle)
    for frame, pause in batch:
        lin.scanner.step(lin.now, FrameIn(frame))
        lin.sims[NODE].step(lin.now, frame)
        lin.run(pause)
    lin.run(0.5)
    assert lin.late_deadlines == []
