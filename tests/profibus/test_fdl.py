"""FDL telegram codec and streaming decoder (fact sheet 1.2, 1.3)."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.profibus.codec.fdl import (
    NEED_MORE,
    SHORT_ACK,
    DataTelegram,
    Discarded,
    FcbState,
    RequestFc,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    ShortAck,
    SlaveFcbMemory,
    StartDelimiter,
    StationType,
    Telegram,
    TelegramDecoder,
    TokenTelegram,
    decode_fc,
    decode_telegram,
    fcs,
)
from adapters.profibus.errors import DecodeFailure, FdlDecodeError
from gateway.errors import FrameDecodeError, FrameEncodeError

h = bytes.fromhex
FAST = settings(max_examples=60, deadline=None)

# --------------------------------------------------------------------------- golden

# Fact sheet 1.2 "Example frames" (master 2 -> slave 5), 1.6, 1.9 and 1.10 examples.
GOLDEN: list[tuple[str, Telegram]] = [
    (
        "10 05 02 49 50 16",  # 1.2 FDL-status request
        DataTelegram(5, 2, RequestFc(RequestFunction.FDL_STATUS)),
    ),
    (
        "68 05 05 68 85 82 6D 3C 3E EE 16",  # 1.2 first Slave_Diag
        DataTelegram(5, 2, RequestFc(RequestFunction.SRD_HIGH, fcb=True), 60, 62),
    ),
    (
        "68 07 07 68 05 02 5D 04 7F 20 00 07 16",  # 1.2 Data_Exchange, 4 output bytes
        DataTelegram(5, 2, RequestFc(RequestFunction.SRD_HIGH, fcv=True), data=h("047F2000")),
    ),
    (
        "68 0F 0F 68 85 82 5D 3D 3E 88 01 0A 0B 80 B5 00 00 00 00 B2 16",  # 1.6 Set_Prm
        DataTelegram(
            5,
            2,
            RequestFc(RequestFunction.SRD_HIGH, fcv=True),
            61,
            62,
            h("88 01 0A 0B 80 B5 00 00 00 00"),
        ),
    ),
    (
        "68 07 07 68 FF 82 46 3A 3E 00 00 3F 16",  # 1.9 Global_Control
        DataTelegram(127, 2, RequestFc(RequestFunction.SDN_HIGH), 58, 62, h("0000")),
    ),
    (
        "68 09 09 68 85 82 7D 33 33 5E 00 2F F0 67 16",  # 1.10 MSAC_C1 read index 47
        DataTelegram(
            5, 2, RequestFc(RequestFunction.SRD_HIGH, True, True), 51, 51, h("5E 00 2F F0")
        ),
    ),
    ("E5", SHORT_ACK),  # 1.2 SC
    ("DC 05 02", TokenTelegram(5, 2)),  # 1.2 SD4 layout (computed)
    (
        # SD3 (LE = 11): 8 bytes after FC; response DL from 5 to 2, computed from 1.2
        "A2 02 05 08 01 02 03 04 05 06 07 08 33 16",
        DataTelegram(2, 5, ResponseFc(ResponseStatus.DL), data=h("0102030405060708")),
    ),
    (
        # Slave_Diag reply 5 -> 2, DSAP 62 SSAP 60 (1.2 "replies swap the SAPs"), computed:
        # LE = 11 (2 SAPs + 6 diag bytes), so it travels as SD3
        "A2 82 85 08 3E 3C 02 05 00 FF 80 B5 C4 16",
        DataTelegram(2, 5, ResponseFc(ResponseStatus.DL), 62, 60, h("02 05 00 FF 80 B5")),
    ),
]


@pytest.mark.parametrize(("wire", "telegram"), GOLDEN)
def test_golden_decode(wire: str, telegram: Telegram) -> None:
    assert decode_telegram(h(wire)) == telegram


@pytest.mark.parametrize(("wire", "telegram"), GOLDEN)
def test_golden_encode(wire: str, telegram: Telegram) -> None:
    assert telegram.encode() == h(wire)


def test_fcs_is_sum_from_da_to_du_mod_256() -> None:
    assert fcs(h("85 82 6D 3C 3E")) == 0xEE
    assert fcs(b"\xff\x01") == 0


def test_delimiter_choice_follows_length() -> None:
    fc = RequestFc(RequestFunction.SRD_HIGH)
    assert DataTelegram(5, 2, fc).delimiter is StartDelimiter.SD1
    assert DataTelegram(5, 2, fc, data=bytes(8)).delimiter is StartDelimiter.SD3
    assert DataTelegram(5, 2, fc, 1, 2, bytes(6)).delimiter is StartDelimiter.SD3
    assert DataTelegram(5, 2, fc, data=bytes(7)).delimiter is StartDelimiter.SD2
    assert DataTelegram(5, 2, fc, data=bytes(9)).delimiter is StartDelimiter.SD2


def test_non_canonical_sd2_is_accepted() -> None:
    # LE 3 in an SD2 decodes (pyprofibus accepts LE 3..249), re-encodes as SD1
    t = decode_telegram(h("68 03 03 68 05 02 49 50 16"))
    assert t == DataTelegram(5, 2, RequestFc(RequestFunction.FDL_STATUS))
    assert t.encode() == h("10 05 02 49 50 16")


def test_max_lengths() -> None:
    fc = ResponseFc(ResponseStatus.DL)
    full = DataTelegram(2, 5, fc, 62, 60, bytes(244))
    assert full.length == 249
    assert decode_telegram(full.encode()) == full
    long = DataTelegram(2, 5, fc, data=bytes(246))
    assert decode_telegram(long.encode()) == long
    with pytest.raises(FrameEncodeError):
        DataTelegram(2, 5, fc, 62, 60, bytes(245)).encode()
    with pytest.raises(FrameEncodeError):
        DataTelegram(2, 5, fc, data=bytes(247)).encode()


def test_only_dsap_or_only_ssap() -> None:
    fc = RequestFc(RequestFunction.SRD_LOW)
    for t in (DataTelegram(5, 2, fc, dsap=10), DataTelegram(5, 2, fc, ssap=10, data=b"x")):
        assert decode_telegram(t.encode()) == t


@pytest.mark.parametrize(
    "bad",
    [
        DataTelegram(128, 2, RequestFc(RequestFunction.SRD_HIGH)),
        DataTelegram(5, -1, RequestFc(RequestFunction.SRD_HIGH)),
        DataTelegram(5, 2, RequestFc(RequestFunction.SRD_HIGH), dsap=64),
        TokenTelegram(5, 200),
    ],
)
def test_encode_rejects_out_of_range(bad: Telegram) -> None:
    with pytest.raises(FrameEncodeError):
        bad.encode()


# --------------------------------------------------------------------------- frame control


@pytest.mark.parametrize(
    ("value", "fc"),
    [
        (0x49, RequestFc(RequestFunction.FDL_STATUS)),  # 1.3 "FC values you will use"
        (0x6D, RequestFc(RequestFunction.SRD_HIGH, fcb=True, fcv=False)),
        (0x5D, RequestFc(RequestFunction.SRD_HIGH, fcb=False, fcv=True)),
        (0x7D, RequestFc(RequestFunction.SRD_HIGH, fcb=True, fcv=True)),
        (0x4C, RequestFc(RequestFunction.SRD_LOW)),
        (0x6C, RequestFc(RequestFunction.SRD_LOW, fcb=True)),
        (0x5C, RequestFc(RequestFunction.SRD_LOW, fcv=True)),
        (0x7C, RequestFc(RequestFunction.SRD_LOW, True, True)),
        (0x46, RequestFc(RequestFunction.SDN_HIGH)),
        (0x44, RequestFc(RequestFunction.SDN_LOW)),
        (0x08, ResponseFc(ResponseStatus.DL)),
        (0x0A, ResponseFc(ResponseStatus.DH)),
        (0x00, ResponseFc(ResponseStatus.OK)),
        (0x03, ResponseFc(ResponseStatus.RS)),
        (0x20, ResponseFc(ResponseStatus.OK, StationType.MASTER_READY)),
        (0x30, ResponseFc(ResponseStatus.OK, StationType.MASTER_IN_RING)),
    ],
)
def test_fc_values(value: int, fc: RequestFc | ResponseFc) -> None:
    assert decode_fc(value) == fc
    assert fc.encode() == value
    assert fc.is_request == bool(value & 0x40)


@pytest.mark.parametrize("value", [0x80, 0xC9, 0x41, 0x42, 0x48, 0x4A, 0x4B, 0x04, 0x0B, 0x0E])
def test_fc_reserved_and_unknown_codes_are_typed_errors(value: int) -> None:
    with pytest.raises(FdlDecodeError) as info:
        decode_fc(value, bytes((value,)))
    assert info.value.reason is DecodeFailure.BAD_FRAME_CONTROL
    assert info.value.raw == bytes((value,))


def test_fcb_sequence_for_one_slave() -> None:
    state = FcbState.reset()
    fcs_seen = []
    for _ in range(4):
        fcs_seen.append(state.fc(RequestFunction.SRD_HIGH).encode())
        state = state.acknowledged()
    assert fcs_seen == [0x6D, 0x5D, 0x7D, 0x5D]  # 1.3: 0x6D first, then alternate
    # a retry resends with the same FCB: the state only moves on acknowledged()
    assert state.fc(RequestFunction.SRD_HIGH) == state.fc(RequestFunction.SRD_HIGH)
    # SDN and status requests never carry FCB/FCV
    assert state.fc(RequestFunction.SDN_HIGH).encode() == 0x46
    assert state.fc(RequestFunction.FDL_STATUS).encode() == 0x49
    assert FcbState.unsequenced(RequestFunction.SDN_LOW).encode() == 0x44


def test_slave_fcb_memory_detects_repeats() -> None:
    mem = SlaveFcbMemory()
    master = FcbState.reset()
    repeat, mem = mem.receive(master.fc(RequestFunction.SRD_HIGH))
    assert not repeat  # FCV = 0: new sequence
    master = master.acknowledged()
    repeat, mem = mem.receive(master.fc(RequestFunction.SRD_HIGH))
    assert not repeat
    repeat, mem = mem.receive(master.fc(RequestFunction.SRD_HIGH))  # master retried
    assert repeat
    master = master.acknowledged()
    repeat, mem = mem.receive(master.fc(RequestFunction.SRD_HIGH))
    assert not repeat
    assert mem.receive(RequestFc(RequestFunction.SDN_HIGH)) == (False, mem)


# --------------------------------------------------------------------------- decode errors


@pytest.mark.parametrize(
    ("wire", "reason"),
    [
        ("", DecodeFailure.TRUNCATED),
        ("00", DecodeFailure.NO_START_DELIMITER),
        ("10 05 02 49 51 16", DecodeFailure.BAD_CHECKSUM),
        ("10 05 02 49 50 17", DecodeFailure.BAD_END_DELIMITER),
        ("10 85 02 49 D0 16", DecodeFailure.BAD_ADDRESS),  # SD1 has no room for a DSAP
        ("10 05 02 C9 D0 16", DecodeFailure.BAD_FRAME_CONTROL),
        ("10 05 02 41 48 16", DecodeFailure.BAD_FRAME_CONTROL),
        ("10 05 02 49 50", DecodeFailure.TRUNCATED),
        ("10 05 02 49 50 16 16", DecodeFailure.TRAILING_BYTES),
        ("68 05 06 68 85 82 6D 3C 3E EE 16", DecodeFailure.BAD_LENGTH),
        ("68 02 02 68 05 02 07 16", DecodeFailure.BAD_LENGTH),
        ("68 FA FA 68", DecodeFailure.BAD_LENGTH),
        ("68 05 05 10 85 82 6D 3C 3E EE 16", DecodeFailure.BAD_LENGTH),
        ("68 05 05", DecodeFailure.TRUNCATED),
        ("68 05 05 68 85 82 6D 3C 3E EE", DecodeFailure.TRUNCATED),
        ("68 05 05 68 85 82 6D 7C 3E 2E 16", DecodeFailure.BAD_ADDRESS),  # segment bit
        ("68 03 03 68 85 02 6D F4 16", DecodeFailure.BAD_ADDRESS),  # DSAP byte missing
        ("A2 02 05 08 01 02 16", DecodeFailure.TRUNCATED),
        ("DC 05 82", DecodeFailure.BAD_ADDRESS),
        ("DC 05", DecodeFailure.TRUNCATED),
        ("E5 E5", DecodeFailure.TRAILING_BYTES),
    ],
)
def test_decode_errors_are_typed_and_carry_raw(wire: str, reason: DecodeFailure) -> None:
    with pytest.raises(FdlDecodeError) as info:
        decode_telegram(h(wire))
    assert info.value.reason is reason
    assert info.value.raw == h(wire)
    assert isinstance(info.value, FrameDecodeError)
    assert isinstance(info.value, ValueError)


# --------------------------------------------------------------------------- strategies

addresses = st.integers(0, 127)
saps = st.none() | st.integers(0, 63)
request_fcs = st.builds(RequestFc, st.sampled_from(RequestFunction), st.booleans(), st.booleans())
response_fcs = st.builds(ResponseFc, st.sampled_from(ResponseStatus), st.sampled_from(StationType))


@st.composite
def data_telegrams(draw: st.DrawFn) -> DataTelegram:
    dsap, ssap = draw(saps), draw(saps)
    room = 246 - (dsap is not None) - (ssap is not None)
    data = draw(st.binary(max_size=room) | st.binary(max_size=12))
    fc = draw(request_fcs | response_fcs)
    return DataTelegram(draw(addresses), draw(addresses), fc, dsap, ssap, data)


telegrams: st.SearchStrategy[Telegram] = st.one_of(
    data_telegrams(), st.builds(TokenTelegram, addresses, addresses), st.just(SHORT_ACK)
)


@FAST
@given(telegrams)
def test_round_trip(telegram: Telegram) -> None:
    assert decode_telegram(telegram.encode()) == telegram


@FAST
@given(st.binary(max_size=40))
def test_decode_telegram_raises_only_typed_errors(raw: bytes) -> None:
    try:
        decode_telegram(raw)
    except FdlDecodeError as exc:
        assert exc.raw == raw


@FAST
@given(st.integers(0, 255))
def test_decode_fc_total(value: int) -> None:
    try:
        fc = decode_fc(value)
    except FdlDecodeError:
        return
    assert fc.encode() == value


# --------------------------------------------------------------------------- streaming

IDLE = None


def drain(decoder: TelegramDecoder) -> list[object]:
    events: list[object] = []
    while (event := decoder.next_frame()) is not NEED_MORE:
        events.append(event)
    return events


def run(
    chunks: list[bytes | None], *, take_whole: bool = False
) -> tuple[TelegramDecoder, list[object]]:
    """Feed chunks (None = the line went idle), draining after each step.

    ``take_whole``: as the driver reads, a chunk that is a whole telegram seen before is
    taken at once (``TelegramDecoder.whole``), the others fed.
    """
    decoder = TelegramDecoder()
    events: list[object] = []
    for chunk in chunks:
        known = decoder.whole(chunk) if take_whole and chunk is not IDLE else None
        if known is not None:
            events.append(known)
            continue
        if chunk is IDLE:
            decoder.mark_idle()
        else:
            decoder.feed(chunk)
        events += drain(decoder)
    return decoder, events


def only_telegrams(events: list[object]) -> list[object]:
    return [e for e in events if not isinstance(e, Discarded)]


def split(data: bytes, cuts: list[int]) -> list[bytes | None]:
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


def is_subsequence(wanted: list[Telegram], got: list[object]) -> bool:
    it = iter(got)
    return all(any(g == w for g in it) for w in wanted)


def test_stream_two_frames_byte_by_byte() -> None:
    wire = h("10 05 02 49 50 16") + h("E5") + h("68 05 05 68 85 82 6D 3C 3E EE 16")
    decoder = TelegramDecoder()
    events: list[object] = []
    for byte in wire:
        decoder.feed(bytes((byte,)))
        events += drain(decoder)
    assert events == [decode_telegram(h(GOLDEN[0][0])), SHORT_ACK, GOLDEN[1][1]]
    assert decoder.stats.telegrams == 3
    assert decoder.stats.telegram_bytes == len(wire)
    assert decoder.stats.decode_errors == 0


def test_stream_resyncs_after_garbage_and_counts_it() -> None:
    wire = h("00 FF 10 77") + h(GOLDEN[1][0])
    decoder, events = run([wire])
    assert isinstance(events[0], Discarded)
    assert events[0].raw == h("00 FF 10 77")
    assert events[0].error.reason is DecodeFailure.NO_START_DELIMITER
    assert events[1:] == [GOLDEN[1][1]]
    assert decoder.stats.discarded_bytes == 4
    assert decoder.stats.decode_errors == 1


def test_stream_bad_fcs_is_discarded_then_next_frame() -> None:
    _, events = run([h("10 05 02 49 51 16 E5")])
    assert isinstance(events[0], Discarded)
    assert events[0].error.reason is DecodeFailure.BAD_CHECKSUM
    assert events[0].raw == h("10 05 02 49 51 16")
    assert events[1:] == [SHORT_ACK]


def test_stream_failed_candidate_loses_only_its_start_byte() -> None:
    # a stray 0x10 before a good SD1: the first candidate fails, the real frame survives
    _, events = run([h("10 10 05 02 49 50 16")])
    assert isinstance(events[0], Discarded)
    assert events[0].raw == h("10")
    assert events[1:] == [GOLDEN[0][1]]


def test_stream_waits_for_a_partial_frame_until_idle() -> None:
    decoder = TelegramDecoder()
    decoder.feed(h("68 0F 0F 68 85 82"))
    assert decoder.next_frame() is NEED_MORE
    assert decoder.buffered == 6
    decoder.mark_idle()  # no gaps inside a frame: this one is dead
    event = decoder.next_frame()
    assert isinstance(event, Discarded)
    assert event.error.reason is DecodeFailure.TRUNCATED
    assert event.raw == h("68 0F 0F 68 85 82")
    assert decoder.next_frame() is NEED_MORE
    assert decoder.buffered == 0


def test_stream_idle_mark_separates_garbage_from_the_next_frame() -> None:
    # "DC" at the end of garbage would swallow two bytes of the frame as a token
    # without the idle mark; with it the frame is intact.
    _, events = run([h("DC"), IDLE, h(GOLDEN[0][0])])
    assert only_telegrams(events) == [GOLDEN[0][1]]


def test_stream_bad_sd2_header_fails_early() -> None:
    decoder = TelegramDecoder()
    decoder.feed(h("68 05 06"))
    event = decoder.next_frame()
    assert isinstance(event, Discarded)
    assert event.error.reason is DecodeFailure.BAD_LENGTH


def test_stream_reset_drops_buffer_keeps_counters() -> None:
    decoder, _ = run([h("E5 00")])
    decoder.feed(h("68 05"))
    decoder.reset()
    assert decoder.buffered == 0
    assert decoder.next_frame() is NEED_MORE
    assert decoder.stats.telegrams == 1
    assert decoder.stats.discarded_bytes == 1


@FAST
@given(st.lists(telegrams, min_size=1, max_size=6), st.lists(st.integers(0, 2000), max_size=8))
def test_stream_random_splits_of_valid_frames(frames: list[Telegram], cuts: list[int]) -> None:
    wire = b"".join(t.encode() for t in frames)
    decoder, events = run(split(wire, cuts))
    assert events == frames
    assert decoder.buffered == 0
    assert decoder.stats.telegram_bytes == len(wire)


chunks = st.lists(st.binary(max_size=30) | st.just(IDLE), max_size=12)


@settings(max_examples=120, deadline=None)
@given(chunks)
def test_stream_random_bytes_never_raise_and_account_for_every_byte(
    stream: list[bytes | None],
) -> None:
    decoder, events = run([*stream, IDLE])
    for event in events:
        assert isinstance(event, DataTelegram | TokenTelegram | ShortAck | Discarded)
    fed = sum(len(c) for c in stream if c is not None)
    stats = decoder.stats
    assert stats.telegram_bytes + stats.discarded_bytes == fed
    assert decoder.buffered == 0  # the final idle mark flushes everything
    assert stats.decode_errors == sum(isinstance(e, Discarded) for e in events)


@FAST
@given(st.binary(min_size=1, max_size=60), telegrams)
def test_stream_recovers_on_the_next_good_frame_after_garbage(
    garbage: bytes, good: Telegram
) -> None:
    # TSYN (>= 33 idle bits) precedes every request on the line: the link marks it
    _, events = run([garbage, IDLE, good.encode(), IDLE])
    assert only_telegrams(events)[-1] == good


@FAST
@given(st.binary(min_size=1, max_size=60), telegrams)
def test_stream_recovers_without_idle_when_garbage_has_no_start_byte(
    garbage: bytes, good: Telegram
) -> None:
    noise = bytes(b for b in garbage if b not in (0x10, 0x68, 0xA2, 0xDC, 0xE5)) or b"\x00"
    decoder, events = run([noise + good.encode()])
    assert events == [events[0], good]
    assert isinstance(events[0], Discarded)
    assert decoder.stats.discarded_bytes == len(noise)


@FAST
@given(
    st.lists(telegrams, min_size=2, max_size=5),
    st.integers(0, 10_000),
    st.lists(st.integers(0, 7), min_size=1, max_size=3),
    st.lists(st.integers(0, 2000), max_size=6),
)
def test_stream_bit_flips_lose_only_the_damaged_frame(
    frames: list[Telegram], which: int, bits: list[int], cuts: list[int]
) -> None:
    victim = which % len(frames)
    damaged = bytearray(frames[victim].encode())
    for i, bit in enumerate(bits):
        damaged[(which + i * 7) % len(damaged)] ^= 1 << bit
    stream: list[bytes | None] = []
    for i, frame in enumerate(frames):
        wire = bytes(damaged) if i == victim else frame.encode()
        stream += [*split(wire, cuts), IDLE]
    _, events = run(stream)
    good = [f for i, f in enumerate(frames) if i != victim]
    assert is_subsequence(good, only_telegrams(events))


def seen(events: list[object]) -> list[object]:
    """Events comparable by value (an error is an exception: compare what it says)."""
    return [(e.error.reason, e.raw) if isinstance(e, Discarded) else e for e in events]


def test_whole_takes_only_a_telegram_seen_before_with_nothing_buffered() -> None:
    reply = h(GOLDEN[1][0])
    decoder = TelegramDecoder()
    assert decoder.whole(reply) is None  # never decoded: feed it
    decoder.feed(reply)
    assert drain(decoder) == [GOLDEN[1][1]]
    assert decoder.whole(reply) == GOLDEN[1][1]
    assert decoder.stats.telegrams == 2
    assert decoder.stats.telegram_bytes == 2 * len(reply)
    decoder.feed(h("68 05"))  # half a telegram waits: the same bytes are no telegram now
    assert decoder.whole(reply) is None
    assert decoder.stats.telegrams == 2
    assert decoder.buffered == 2


@FAST
@given(
    st.lists(
        st.sampled_from([t.encode() for _, t in GOLDEN]) | st.binary(max_size=20), max_size=12
    ),
    st.lists(st.booleans(), max_size=12),
)
def test_taking_whole_telegrams_changes_no_event_and_no_count(
    parts: list[bytes], idles: list[bool]
) -> None:
    stream: list[bytes | None] = []
    for i, part in enumerate(parts):
        stream.append(part)
        if i < len(idles) and idles[i]:
            stream.append(IDLE)
    stream.append(IDLE)
    plain, plain_events = run(stream)
    taking, taking_events = run(stream, take_whole=True)
    assert seen(taking_events) == seen(plain_events)
    assert taking.stats == plain.stats
    assert taking.buffered == plain.buffered == 0
