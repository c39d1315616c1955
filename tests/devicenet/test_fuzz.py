"""Every DeviceNet decoder on random frames: random 11-bit ids, 0-8 random bytes.

Whatever the input, only DeviceNetDecodeError subclasses (FrameDecodeError) escape.
"""

from __future__ import annotations

from collections.abc import Callable

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.datatypes import CipType, decode_short_string, decode_value
from adapters.devicenet.dupmac import DupMacCheck
from adapters.devicenet.errors import DeviceNetDecodeError
from adapters.devicenet.explicit import BodyFormat, ExplicitMessage
from adapters.devicenet.fragment import (
    ExplicitFragment,
    ExplicitReassembler,
    IoFragment,
    IoReassembler,
    decode_explicit_frame,
)
from adapters.devicenet.frame import CanFrame
from adapters.devicenet.ids import decode_can_id, match_predefined
from adapters.devicenet.objects import AllocationInfo
from gateway.errors import FrameDecodeError
from tests.devicenet.strategies import frames


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
