"""Fragmentation protocol, explicit and I/O (fact sheet 2.8)."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.devicenet.codec.explicit import ExplicitMessage, SuccessResponse
from adapters.devicenet.codec.fragment import (
    ExplicitFragment,
    ExplicitReassembler,
    ExplicitSender,
    FragmentAck,
    FragmentType,
    IoFragment,
    IoReassembler,
    Unfragmented,
    decode_explicit_frame,
    explicit_payloads,
    fragment_explicit,
    fragment_io,
)
from adapters.devicenet.errors import (
    FragmentAckError,
    FragmentAckTimeout,
    FragmentationError,
    FragmentDecodeError,
    FragmentOutOfSequence,
    ReassembledTooLong,
    ReassemblyTimeout,
)
from gateway.errors import FrameEncodeError

FIRST, MIDDLE, LAST = FragmentType.FIRST, FragmentType.MIDDLE, FragmentType.LAST

# Get_Attribute_Single reply with the Identity product name "CFW-08" (seed table 8) as a
# SHORT_STRING: 9 bytes, so two fragments. Frames computed from fact sheet 2.8.
NAME_REPLY = bytes.fromhex("00 8E 06 43 46 57 2D 30 38")
NAME_FRAMES = [bytes.fromhex("80 00 8E 06 43 46 57 2D"), bytes.fromhex("80 81 30 38")]
NAME_ACKS = [bytes.fromhex("80 C0 00"), bytes.fromhex("80 C1 00")]

# Get_Attributes_All reply of the Identity object: vendor 355h, type 2, code 1,
# revision 4.6, status 0, serial 1, name "CFW-08": 23 bytes, four fragments.
IDENTITY_REPLY = bytes.fromhex(
    "00 81 55 03 02 00 01 00 04 06 00 00 01 00 00 00 06 43 46 57 2D 30 38"
)
IDENTITY_FRAMES = [
    bytes.fromhex("80 00 81 55 03 02 00 01"),
    bytes.fromhex("80 41 00 04 06 00 00 01"),
    bytes.fromhex("80 42 00 00 00 06 43 46"),
    bytes.fromhex("80 83 57 2D 30 38"),
]

explicit_messages = st.builds(
    lambda header, body: bytes((header,)) + body,
    st.integers(0, 0x7F),
    st.binary(min_size=8, max_size=200),
)


def _run_exchange(message: bytes) -> tuple[bytes, int]:
    """Send ``message`` through a sender and a reassembler, acks going back."""
    sender, receiver = ExplicitSender(message), ExplicitReassembler()
    frame: bytes | None = sender.start(0.0)
    frames, now = 0, 0.0
    result = None
    while frame is not None:
        frames += 1
        now += 0.01
        sorted_frame = decode_explicit_frame(frame)
        if isinstance(sorted_frame, Unfragmented):
            return sorted_frame.message, frames
        assert isinstance(sorted_frame, ExplicitFragment)
        step = receiver.feed(now, sorted_frame)
        result = step.message or result
        assert step.ack is not None
        ack = decode_explicit_frame(step.ack.encode())
        assert isinstance(ack, FragmentAck)
        frame = sender.on_ack(now, ack)
    assert sender.done
    assert not sender.failed
    assert result is not None
    return result, frames


# ---------------------------------------------------------------- golden frames


def test_golden_two_fragments_both_directions():
    fragments = fragment_explicit(NAME_REPLY)
    assert [f.encode() for f in fragments] == NAME_FRAMES
    assert [f.ack().encode() for f in fragments] == NAME_ACKS
    assert [decode_explicit_frame(f) for f in NAME_FRAMES] == fragments
    assert [decode_explicit_frame(a) for a in NAME_ACKS] == [FragmentAck(0, 0), FragmentAck(0, 1)]
    receiver = ExplicitReassembler()
    steps = [receiver.feed(0.0, f) for f in fragments]
    assert [s.ack.encode() for s in steps if s.ack] == NAME_ACKS
    assert steps[0].message is None
    assert steps[1].message == NAME_REPLY
    reply = ExplicitMessage.decode(NAME_REPLY)
    assert reply.body == SuccessResponse(0x0E, b"\x06CFW-08")


def test_golden_four_fragments():
    assert explicit_payloads(IDENTITY_REPLY) == IDENTITY_FRAMES
    receiver = ExplicitReassembler()
    messages = []
    for frame in IDENTITY_FRAMES:
        fragment = decode_explicit_frame(frame)
        assert isinstance(fragment, ExplicitFragment)
        messages.append(receiver.feed(0.0, fragment).message)
    assert messages == [None, None, None, IDENTITY_REPLY]


def test_golden_io_fragments():
    data = bytes(range(10))
    frames = [bytes.fromhex("00 00 01 02 03 04 05 06"), bytes.fromhex("81 07 08 09")]
    assert fragment_io(data) == frames
    receiver = IoReassembler()
    assert [receiver.feed(0.0, f).message for f in frames] == [None, data]


def test_short_messages_go_unfragmented():
    assert explicit_payloads(bytes.fromhex("00 0E 64 01 7B")) == [bytes.fromhex("00 0E 64 01 7B")]
    assert fragment_io(b"\x01\x02\x03\x04") == [b"\x01\x02\x03\x04"]
    assert decode_explicit_frame(b"\x00\x8e\x55\x03") == Unfragmented(b"\x00\x8e\x55\x03")
    sender = ExplicitSender(b"\x00\x0e\x64\x01\x7b")
    assert sender.start(0.0) == b"\x00\x0e\x64\x01\x7b"
    assert sender.done
    assert sender.deadline is None
    assert not sender.fragmented


@pytest.mark.parametrize("message", [b"", b"\x00" * 8, b"\x80" + bytes(10)])
def test_fragment_explicit_rejects(message):
    with pytest.raises(FrameEncodeError):
        fragment_explicit(message)


@pytest.mark.parametrize(
    "build",
    [
        lambda: ExplicitFragment(0x80, FIRST, 0),
        lambda: ExplicitFragment(0, FragmentType.ACK, 0),
        lambda: ExplicitFragment(0, FIRST, 64),
        lambda: ExplicitFragment(0, FIRST, 0, bytes(7)),
        lambda: IoFragment(FIRST, 0, bytes(8)),
        lambda: FragmentAck(0, 0, 256),
    ],
)
def test_fragment_encode_errors(build):
    with pytest.raises(FrameEncodeError):
        build()


@pytest.mark.parametrize("frame", ["", "80", "80 C0", "80 C0 00 00"])
def test_bad_explicit_frames(frame):
    with pytest.raises(FragmentDecodeError):
        decode_explicit_frame(bytes.fromhex(frame))


@pytest.mark.parametrize("frame", ["", "C0 00"])
def test_bad_io_frames(frame):
    with pytest.raises(FragmentDecodeError):
        IoFragment.decode(bytes.fromhex(frame))


# ---------------------------------------------------------------- recovery rules


def test_duplicate_fragment_is_acknowledged_again_and_ignored():
    fragments = fragment_explicit(IDENTITY_REPLY)
    receiver = ExplicitReassembler()
    produced = []
    for fragment in fragments:
        first = receiver.feed(0.0, fragment)
        again = receiver.feed(0.0, fragment)
        assert not first.duplicate
        assert again.duplicate
        assert again.ack == first.ack == fragment.ack()
        assert again.message is None
        produced.append(first.message)
    assert produced == [None, None, None, IDENTITY_REPLY]


def test_new_first_fragment_restarts():
    old = fragment_explicit(bytes((0x01,)) + bytes(range(20)))
    new = fragment_explicit(bytes((0x41,)) + bytes(range(100, 115)))
    receiver = ExplicitReassembler()
    receiver.feed(0.0, old[0])
    receiver.feed(0.0, old[1])
    step = receiver.feed(0.0, new[0])
    assert step.restarted
    assert [receiver.feed(0.0, f).message for f in new[1:]][-1] == bytes((0x41,)) + bytes(
        range(100, 115)
    )


def test_missing_fragment_discards_the_partial_message():
    fragments = fragment_explicit(IDENTITY_REPLY)
    receiver = ExplicitReassembler()
    receiver.feed(0.0, fragments[0])
    with pytest.raises(FragmentOutOfSequence) as info:
        receiver.feed(0.0, fragments[2])
    assert (info.value.expected, info.value.received) == (1, 2)
    assert info.value.raw == IDENTITY_FRAMES[2]
    assert not receiver.in_progress
    with pytest.raises(FragmentOutOfSequence) as info:
        receiver.feed(0.0, fragments[1])  # too late: nothing in progress
    assert info.value.expected is None


def test_fragment_of_another_header_is_out_of_sequence():
    receiver = ExplicitReassembler()
    receiver.feed(0.0, ExplicitFragment(0x00, FIRST, 0, bytes(6)))
    with pytest.raises(FragmentOutOfSequence):
        receiver.feed(0.0, ExplicitFragment(0x40, MIDDLE, 1, bytes(6)))


def test_changed_repeat_is_not_a_duplicate():
    receiver = ExplicitReassembler()
    receiver.feed(0.0, ExplicitFragment(0, FIRST, 0, bytes(6)))
    receiver.feed(0.0, ExplicitFragment(0, MIDDLE, 1, bytes(6)))
    with pytest.raises(FragmentOutOfSequence):
        receiver.feed(0.0, ExplicitFragment(0, MIDDLE, 1, b"\x01" * 6))


def test_timeout_with_injected_clock():
    fragments = fragment_explicit(IDENTITY_REPLY)
    receiver = ExplicitReassembler(timeout=1.0)
    assert receiver.deadline is None
    receiver.feed(10.0, fragments[0])
    receiver.feed(10.5, fragments[1])
    assert receiver.deadline == 11.5
    receiver.tick(11.4)
    with pytest.raises(ReassemblyTimeout) as info:
        receiver.tick(11.5)
    assert info.value.raw == IDENTITY_REPLY[1:13]
    receiver.tick(20.0)  # reported once
    with pytest.raises(FragmentOutOfSequence):
        receiver.feed(11.6, fragments[2])


def test_late_fragment_without_tick_is_out_of_sequence():
    fragments = fragment_explicit(IDENTITY_REPLY)
    receiver = ExplicitReassembler(timeout=1.0)
    receiver.feed(0.0, fragments[0])
    with pytest.raises(FragmentOutOfSequence):
        receiver.feed(5.0, fragments[1])


def test_too_long_message_is_discarded():
    receiver = ExplicitReassembler(max_length=10)
    fragments = fragment_explicit(bytes(30))
    receiver.feed(0.0, fragments[0])
    with pytest.raises(ReassembledTooLong):
        receiver.feed(0.0, fragments[1])
    assert not receiver.in_progress


def test_count_wraps_modulo_64():
    message = bytes((0x05,)) + bytes(i % 256 for i in range(6 * 70))
    fragments = fragment_explicit(message)
    assert len(fragments) == 70
    assert (fragments[63].count, fragments[64].count) == (63, 0)
    assert fragments[64].kind is MIDDLE
    assert _run_exchange(message) == (message, 70)


# ---------------------------------------------------------------- sender


def test_sender_ignores_other_acks_and_fails_on_bad_status():
    sender = ExplicitSender(IDENTITY_REPLY)
    assert sender.start(0.0) == IDENTITY_FRAMES[0]
    assert sender.deadline == 1.0
    assert sender.on_ack(0.1, FragmentAck(0, 5)) is None  # stale
    assert sender.on_ack(0.1, FragmentAck(0x40, 0)) is None  # other header
    assert sender.on_ack(0.1, FragmentAck(0, 0)) == IDENTITY_FRAMES[1]
    with pytest.raises(FragmentAckError) as info:
        sender.on_ack(0.2, FragmentAck(0, 1, status=1))
    assert info.value.status == 1
    assert sender.done
    assert sender.failed


def test_sender_ack_timeout():
    sender = ExplicitSender(IDENTITY_REPLY, ack_timeout=1.0)
    sender.start(0.0)
    sender.tick(0.9)
    with pytest.raises(FragmentAckTimeout):
        sender.tick(1.0)
    assert sender.failed
    assert sender.on_ack(1.1, FragmentAck(0, 0)) is None
    with pytest.raises(FrameEncodeError):
        sender.start(2.0)


# ---------------------------------------------------------------- properties


@settings(max_examples=60, deadline=None)
@given(explicit_messages)
def test_explicit_exchange_round_trip(message):
    result, frames = _run_exchange(message)
    assert result == message
    assert frames == -(-(len(message) - 1) // 6)


@settings(max_examples=60, deadline=None)
@given(st.binary(min_size=9, max_size=200))
def test_io_round_trip(data):
    frames = fragment_io(data)
    assert all(len(f) <= 8 for f in frames)
    receiver = IoReassembler()
    results = [receiver.feed(0.0, f).message for f in frames]
    assert results[-1] == data
    assert results[:-1] == [None] * (len(frames) - 1)


def _feed_sequence(receiver, frames, order):
    """Feed frames in ``order``; collect complete messages and count typed errors."""
    produced, errors = [], 0
    for now, index in enumerate(order):
        try:
            if isinstance(receiver, ExplicitReassembler):
                fragment = decode_explicit_frame(frames[index])
                assert isinstance(fragment, ExplicitFragment)
                step = receiver.feed(now * 0.01, fragment)
            else:
                step = receiver.feed(now * 0.01, frames[index])
        except FragmentationError:
            errors += 1
            continue
        if step.message is not None:
            produced.append(step.message)
    return produced, errors


def _in_order_with_repeats(order, count):
    deduplicated = [i for n, i in enumerate(order) if n == 0 or order[n - 1] != i]
    return deduplicated == list(range(count))


@settings(max_examples=150, deadline=None)
@given(explicit_messages, st.data())
def test_explicit_disorder_yields_the_original_or_typed_errors(message, data):
    frames = explicit_payloads(message)
    order = data.draw(st.lists(st.integers(0, len(frames) - 1), max_size=3 * len(frames)))
    produced, _ = _feed_sequence(ExplicitReassembler(), frames, order)
    assert all(m == message for m in produced)
    if _in_order_with_repeats(order, len(frames)):
        assert produced == [message]


@settings(max_examples=150, deadline=None)
@given(st.binary(min_size=9, max_size=120), st.data())
def test_io_disorder_yields_the_original_or_typed_errors(payload, data):
    frames = fragment_io(payload)
    order = data.draw(st.lists(st.integers(0, len(frames) - 1), max_size=3 * len(frames)))
    produced, _ = _feed_sequence(IoReassembler(), frames, order)
    assert all(m == payload for m in produced)
    if _in_order_with_repeats(order, len(frames)):
        assert produced == [payload]


@settings(max_examples=60, deadline=None)
@given(explicit_messages, st.data())
def test_in_order_with_losses_never_completes_wrongly(message, data):
    frames = explicit_payloads(message)
    kept = data.draw(st.lists(st.booleans(), min_size=len(frames), max_size=len(frames)))
    order = [i for i, keep in enumerate(kept) if keep]
    produced, errors = _feed_sequence(ExplicitReassembler(), frames, order)
    if all(kept):
        assert produced == [message]
    else:
        assert produced == []
        assert errors or not kept[-1] or not any(kept)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=8), max_size=20))
def test_fuzz_reassemblers_raise_only_typed_errors(frames):
    explicit, io = ExplicitReassembler(), IoReassembler()
    for now, frame in enumerate(frames):
        with contextlib.suppress(FragmentationError):
            _feed_explicit(explicit, now, frame)
        with contextlib.suppress(FragmentationError):
            io.feed(float(now), frame)
        with contextlib.suppress(FragmentationError):
            explicit.tick(float(now))
        with contextlib.suppress(FragmentationError):
            io.tick(float(now))


def _feed_explicit(receiver: ExplicitReassembler, now: int, frame: bytes) -> None:
    sorted_frame = decode_explicit_frame(frame)
    if isinstance(sorted_frame, ExplicitFragment):
        receiver.feed(float(now), sorted_frame)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=8))
def test_fuzz_frame_decoders_are_typed_and_canonical(frame):
    try:
        sorted_frame = decode_explicit_frame(frame)
    except FragmentDecodeError as exc:
        assert exc.raw == frame
    else:
        encoded = (
            sorted_frame.message
            if isinstance(sorted_frame, Unfragmented)
            else sorted_frame.encode()
        )
        assert encoded == frame
    try:
        io_fragment = IoFragment.decode(frame)
    except FragmentDecodeError as exc:
        assert exc.raw == frame
    else:
        assert io_fragment.encode() == frame
