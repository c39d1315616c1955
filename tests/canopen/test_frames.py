"""CANopen frames: golden bytes from CiA 301 and round trips."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.canopen.codec import codes
from adapters.canopen.codec import frames as f
from adapters.canopen.errors import (
    CanOpenDecodeError,
    EmcyDecodeError,
    InvalidCobId,
    NmtDecodeError,
    SdoDecodeError,
)
from gateway.errors import FrameDecodeError, FrameEncodeError, GatewayError
from tests.support.canframes import DATA, IDENTIFIERS, carried


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# --- COB-IDs (CiA 301 §7.3.3) ---


def test_predefined_cob_ids_of_node_5() -> None:
    assert f.emcy_id(5) == 0x085
    assert [f.tpdo_id(n, 5) for n in (1, 2, 3, 4)] == [0x185, 0x285, 0x385, 0x485]
    assert [f.rpdo_id(n, 5) for n in (1, 2, 3, 4)] == [0x205, 0x305, 0x405, 0x505]
    assert f.sdo_tx_id(5) == 0x585
    assert f.sdo_rx_id(5) == 0x605
    assert f.heartbeat_id(5) == 0x705


def test_classify() -> None:
    assert f.classify(0x000) == f.CobId(f.Kind.NMT)
    assert f.classify(0x080) == f.CobId(f.Kind.SYNC)
    assert f.classify(0x0FF) == f.CobId(f.Kind.EMCY, 127)
    assert f.classify(0x1A5) == f.CobId(f.Kind.TPDO, 0x25, 1)
    assert f.classify(0x305) == f.CobId(f.Kind.RPDO, 5, 2)
    assert f.classify(0x485) == f.CobId(f.Kind.TPDO, 5, 4)
    assert f.classify(0x585) == f.CobId(f.Kind.SDO_TX, 5)
    assert f.classify(0x605) == f.CobId(f.Kind.SDO_RX, 5)
    assert f.classify(0x77F) == f.CobId(f.Kind.HEARTBEAT, 127)


@pytest.mark.parametrize("cob_id", [0x800, -1, 0x180, 0x680, 0x6A0])
def test_classify_refuses(cob_id: int) -> None:
    with pytest.raises(InvalidCobId):
        f.classify(cob_id)


@given(st.integers(1, 127), st.integers(1, 4))
def test_cob_id_round_trip(node: int, pdo: int) -> None:
    assert f.classify(f.tpdo_id(pdo, node)) == f.CobId(f.Kind.TPDO, node, pdo)
    assert f.classify(f.rpdo_id(pdo, node)) == f.CobId(f.Kind.RPDO, node, pdo)
    assert f.classify(f.heartbeat_id(node)).node_id == node


@pytest.mark.parametrize("node", [0, 128, True])
def test_node_id_range(node: int) -> None:
    with pytest.raises(FrameEncodeError):
        f.sdo_rx_id(node)


# --- NMT, heartbeat, SYNC, EMCY ---


def test_nmt_golden() -> None:
    assert f.encode_nmt(f.NmtCommand.START, 5) == f.CanFrame(0x000, h("01 05"))
    assert f.encode_nmt(f.NmtCommand.START) == f.CanFrame(0x000, h("01 00"))
    assert f.encode_nmt(f.NmtCommand.RESET_NODE, 0x10).data == h("81 10")
    assert f.encode_nmt(f.NmtCommand.ENTER_PRE_OPERATIONAL, 1).data == h("80 01")
    assert f.decode_nmt(h("82 7f")) == f.Nmt(f.NmtCommand.RESET_COMMUNICATION, 127)


@pytest.mark.parametrize("raw", ["01", "01 05 00", "03 05", "01 80"])
def test_nmt_decode_errors(raw: str) -> None:
    with pytest.raises(NmtDecodeError):
        f.decode_nmt(h(raw))


def test_heartbeat_golden() -> None:
    assert f.encode_heartbeat(5, f.NmtState.BOOTUP) == f.CanFrame(0x705, h("00"))
    assert f.encode_heartbeat(5, f.NmtState.OPERATIONAL) == f.CanFrame(0x705, h("05"))
    assert f.encode_heartbeat(5, f.NmtState.PRE_OPERATIONAL).data == h("7f")
    assert f.decode_heartbeat(h("04")) is f.NmtState.STOPPED
    assert f.decode_heartbeat(h("85")) is f.NmtState.OPERATIONAL  # toggle bit ignored
    for raw in ("", "05 00", "06"):
        with pytest.raises(NmtDecodeError):
            f.decode_heartbeat(h(raw), cob_id=0x705)


def test_sync_golden() -> None:
    assert f.encode_sync() == f.CanFrame(0x080, b"")
    assert f.encode_sync(240) == f.CanFrame(0x080, h("f0"))
    with pytest.raises(FrameEncodeError):
        f.encode_sync(241)


def test_emcy_golden() -> None:
    frame = f.encode_emcy(5, f.Emcy(0x2310, 0x03))
    assert frame == f.CanFrame(0x085, h("10 23 03 00 00 00 00 00"))
    emcy = f.decode_emcy(h("30 32 05 01 02 03 04 05"))
    assert emcy == f.Emcy(0x3230, 0x05, h("01 02 03 04 05"))
    assert emcy.text == "load error"
    with pytest.raises(EmcyDecodeError):
        f.decode_emcy(h("10 23 03"))


@given(st.integers(0, 0xFFFF), st.integers(0, 0xFF), st.binary(min_size=5, max_size=5))
def test_emcy_round_trip(code: int, register: int, extra: bytes) -> None:
    emcy = f.Emcy(code, register, extra)
    assert f.decode_emcy(f.encode_emcy(1, emcy).data) == emcy


# --- SDO (CiA 301 §7.2.4.3) ---


def test_expedited_download_golden() -> None:
    # 0x1017:00 = 1000 (UNSIGNED16) to node 5: 0x605 2B 17 10 00 E8 03 00 00
    request = f.InitiateDownload(0x1017, 0, (1000).to_bytes(2, "little"))
    assert f.CanFrame(f.sdo_rx_id(5), f.encode_sdo_request(request)) == f.CanFrame(
        0x605, h("2B 17 10 00 E8 03 00 00")
    )
    assert f.decode_sdo_request(h("2B 17 10 00 E8 03 00 00")) == request
    # 1, 3 and 4 bytes: 0x2F, 0x27, 0x23
    assert f.encode_sdo_request(f.InitiateDownload(0x6060, 0, h("03")))[:1] == h("2F")
    assert f.encode_sdo_request(f.InitiateDownload(0x2000, 1, h("01 02 03")))[:1] == h("27")
    assert f.encode_sdo_request(f.InitiateDownload(0x1400, 1, h("05 02 00 00"))) == h(
        "23 00 14 01 05 02 00 00"
    )
    response = f.InitiateDownloadResponse(0x1017, 0)
    assert f.encode_sdo_response(response) == h("60 17 10 00 00 00 00 00")
    assert f.decode_sdo_response(h("60 17 10 00 00 00 00 00")) == response


def test_expedited_upload_golden() -> None:
    assert f.encode_sdo_request(f.InitiateUpload(0x6041, 0)) == h("40 41 60 00 00 00 00 00")
    response = f.InitiateUploadResponse(0x6041, 0, h("37 02"))
    assert f.encode_sdo_response(response) == h("4B 41 60 00 37 02 00 00")
    assert f.decode_sdo_response(h("43 00 10 00 92 01 02 00")) == f.InitiateUploadResponse(
        0x1000, 0, h("92 01 02 00")
    )
    # e=1, s=0: size not indicated, the 4 bytes are the data
    assert f.decode_sdo_response(h("42 00 10 00 92 01 02 00")).data == h("92 01 02 00")  # type: ignore[union-attr]


def test_segmented_golden() -> None:
    # Initiate with size indicated: 0x21 (download) / 0x41 (upload response).
    assert f.encode_sdo_request(f.InitiateDownload(0x1008, 0, b"", expedited=False, size=10)) == h(
        "21 08 10 00 0A 00 00 00"
    )
    assert f.encode_sdo_response(
        f.InitiateUploadResponse(0x1008, 0, b"", expedited=False, size=10)
    ) == h("41 08 10 00 0A 00 00 00")
    # Segments: t in bit 4, n (unused bytes) in bits 3-1, c in bit 0.
    assert f.encode_sdo_request(f.DownloadSegment(False, b"ABCDEFG", False)) == h(
        "00 41 42 43 44 45 46 47"
    )
    assert f.encode_sdo_request(f.DownloadSegment(True, b"HIJ", True)) == h(
        "19 48 49 4A 00 00 00 00"
    )
    assert f.encode_sdo_response(f.DownloadSegmentResponse(True)) == h("30 00 00 00 00 00 00 00")
    assert f.encode_sdo_request(f.UploadSegment(False)) == h("60 00 00 00 00 00 00 00")
    assert f.encode_sdo_request(f.UploadSegment(True)) == h("70 00 00 00 00 00 00 00")
    assert f.decode_sdo_response(h("1B 48 49 00 00 00 00 00")) == f.UploadSegmentResponse(
        True, b"HI", True
    )


def test_abort_golden() -> None:
    abort = f.Abort(0x2000, 1, 0x06090030)
    assert f.encode_sdo_response(abort) == h("80 00 20 01 30 00 09 06")
    assert f.decode_sdo_response(h("80 00 20 01 30 00 09 06")) == abort
    assert abort.text == "value range of parameter exceeded"
    assert f.decode_sdo_request(h("80 00 20 01 30 00 09 06")) == abort


@pytest.mark.parametrize(
    "raw", ["40 41 60 00", "C0 00 00 00 00 00 00 00", "A0 00 00 00 00 00 00 00"]
)
def test_sdo_request_decode_errors(raw: str) -> None:
    with pytest.raises(SdoDecodeError) as info:
        f.decode_sdo_request(h(raw), cob_id=0x605)
    assert isinstance(info.value, FrameDecodeError)
    assert isinstance(info.value, GatewayError)


@pytest.mark.parametrize("raw", ["60", "E0 00 00 00 00 00 00 00", "0E 00 00 00 00 00 00 00"])
def test_sdo_response_decode_errors(raw: str) -> None:
    with pytest.raises(CanOpenDecodeError):
        f.decode_sdo_response(h(raw))


def test_sdo_encode_errors() -> None:
    with pytest.raises(FrameEncodeError):
        f.encode_sdo_request(f.InitiateDownload(0x1017, 0, b"12345"))
    with pytest.raises(FrameEncodeError):
        f.encode_sdo_request(f.DownloadSegment(False, b"12345678", False))
    with pytest.raises(FrameEncodeError):
        f.encode_sdo_request(f.InitiateUpload(0x10000, 0))


_mux = (st.integers(0, 0xFFFF), st.integers(0, 0xFF))


@given(*_mux, st.binary(min_size=1, max_size=4))
def test_expedited_round_trip(index: int, sub: int, data: bytes) -> None:
    request = f.InitiateDownload(index, sub, data)
    assert f.decode_sdo_request(f.encode_sdo_request(request)) == request
    response = f.InitiateUploadResponse(index, sub, data)
    assert f.decode_sdo_response(f.encode_sdo_response(response)) == response


@given(st.booleans(), st.binary(min_size=1, max_size=7), st.booleans())
def test_segment_round_trip(toggle: bool, data: bytes, last: bool) -> None:
    segment = f.DownloadSegment(toggle, data, last)
    assert f.decode_sdo_request(f.encode_sdo_request(segment)) == segment
    reply = f.UploadSegmentResponse(toggle, data, last)
    assert f.decode_sdo_response(f.encode_sdo_response(reply)) == reply


# --- the client transfer against a minimal server ---


class _Server:
    """A dictionary of byte strings answering SDO requests per CiA 301."""

    def __init__(self, objects: dict[tuple[int, int], bytes]) -> None:
        self.objects = objects
        self._upload: bytes = b""
        self._down = bytearray()
        self._key = (0, 0)
        self.toggle = False
        self.break_toggle = False

    def answer(self, data: bytes) -> bytes:
        request = f.decode_sdo_request(data)
        if isinstance(request, f.InitiateUpload):
            key = (request.index, request.subindex)
            if key not in self.objects:
                return f.encode_sdo_response(f.Abort(*key, codes.ABORT_NO_OBJECT))
            value = self.objects[key]
            if len(value) <= 4:
                return f.encode_sdo_response(f.InitiateUploadResponse(*key, value))
            self._upload, self.toggle = value, False
            return f.encode_sdo_response(
                f.InitiateUploadResponse(*key, b"", expedited=False, size=len(value))
            )
        if isinstance(request, f.UploadSegment):
            chunk, self._upload = self._upload[:7], self._upload[7:]
            toggle = request.toggle ^ self.break_toggle
            return f.encode_sdo_response(f.UploadSegmentResponse(toggle, chunk, not self._upload))
        if isinstance(request, f.InitiateDownload):
            self._key = (request.index, request.subindex)
            if request.expedited:
                self.objects[self._key] = request.data
            else:
                self._down = bytearray()
            return f.encode_sdo_response(f.InitiateDownloadResponse(*self._key))
        if isinstance(request, f.DownloadSegment):
            self._down += request.data
            if request.last:
                self.objects[self._key] = bytes(self._down)
            return f.encode_sdo_response(f.DownloadSegmentResponse(request.toggle))
        raise AssertionError(request)


def _run(transfer: f.SdoClientTransfer, server: _Server) -> tuple[f.SdoResult, list[bytes]]:
    sent = [transfer.first()]
    while transfer.result is None:
        nxt = transfer.on_response(server.answer(sent[-1]))
        if nxt is not None:
            sent.append(nxt)
    return transfer.result, sent


def test_client_expedited_read_and_write() -> None:
    server = _Server({(0x6041, 0): h("37 02")})
    result, sent = _run(f.SdoClientTransfer(0x6041, 0), server)
    assert result == f.SdoResult(h("37 02"))
    assert sent == [h("40 41 60 00 00 00 00 00")]
    result, sent = _run(f.SdoClientTransfer(0x1017, 0, h("E8 03")), server)
    assert result.ok
    assert sent == [h("2B 17 10 00 E8 03 00 00")]
    assert server.objects[(0x1017, 0)] == h("E8 03")


def test_client_segmented_read_and_write() -> None:
    name = b"CiA 402 drive, simulated"
    server = _Server({(0x1008, 0): name})
    result, sent = _run(f.SdoClientTransfer(0x1008, 0), server)
    assert result.data == name
    assert sent[1:] == [
        h("60" + "00" * 7),
        h("70" + "00" * 7),
        h("60" + "00" * 7),
        h("70" + "00" * 7),
    ]
    result, sent = _run(f.SdoClientTransfer(0x2000, 5, b"0123456789"), server)
    assert result.ok
    assert sent == [
        h("21 00 20 05 0A 00 00 00"),
        h("00 30 31 32 33 34 35 36"),
        h("19 37 38 39 00 00 00 00"),
    ]
    assert server.objects[(0x2000, 5)] == b"0123456789"


def test_client_server_abort_and_toggle_error() -> None:
    result, _ = _run(f.SdoClientTransfer(0x6077, 0), _Server({}))
    assert result == f.SdoResult(abort_code=0x06020000, by_server=True)
    assert result.message == "0x06020000 object does not exist in the object dictionary"
    server = _Server({(0x1008, 0): b"0123456789ABCDEF"})
    server.break_toggle = True
    transfer = f.SdoClientTransfer(0x1008, 0)
    reply = transfer.on_response(server.answer(transfer.first()))
    assert reply is not None
    abort = transfer.on_response(server.answer(reply))
    assert abort == h("80 08 10 00 00 00 03 05")  # the client aborts: toggle not alternated
    assert transfer.result == f.SdoResult(abort_code=codes.ABORT_TOGGLE)


def test_client_ignores_answers_that_are_not_its_own() -> None:
    """CiA 301 §7.2.4.3: an initiate response names the object; a late answer of a
    transfer the client ended on its timeout is not this transfer's: ignored, no abort
    of its own (that was the 0x05040001 of a bring-up write under overload)."""
    transfer = f.SdoClientTransfer(0x6041, 0)
    transfer.first()
    stale = [
        h("4B 40 60 00 37 02 00 00"),  # upload response for 0x6040: another object
        h("4B 41 60 01 37 02 00 00"),  # 0x6041 sub 1: another sub-index
        h("60 41 60 00 00 00 00 00"),  # download response for 0x6041: the other direction
        h("00 30 31 32 33 34 35 36"),  # upload segment: no segment asked
        h("20 00 00 00 00 00 00 00"),  # download segment response
        h("80 17 10 00 00 00 09 06"),  # abort naming 0x1017: an earlier transfer's
    ]
    for data in stale:
        assert transfer.on_response(data) is None
        assert transfer.result is None
    assert transfer.ignored == len(stale)
    assert transfer.on_response(h("4B 41 60 00 37 02 00 00")) is None
    assert transfer.result == f.SdoResult(h("37 02"))
    # a download: the late upload answer of its own object is not its answer either
    transfer = f.SdoClientTransfer(0x6040, 0, h("06 00"))
    assert transfer.first() == h("2B 40 60 00 06 00 00 00")
    assert transfer.on_response(h("4B 40 60 00 0F 00 00 00")) is None
    assert transfer.on_response(h("60 40 60 00 00 00 00 00")) is None
    assert transfer.result == f.SdoResult()
    # an abort naming no object (a server that does not say) is taken as this one's
    transfer = f.SdoClientTransfer(0x6040, 0, h("06 00"))
    transfer.first()
    transfer.on_response(h("80 00 00 00 01 00 04 05"))
    assert transfer.result == f.SdoResult(abort_code=codes.ABORT_COMMAND, by_server=True)


def test_client_wrong_object_in_segments_and_timeout() -> None:
    # segments under way: a response of the wrong kind is a protocol error, aborted
    transfer = f.SdoClientTransfer(0x1008, 0)
    transfer.first()
    assert transfer.on_response(h("41 08 10 00 10 00 00 00")) == h("60 00 00 00 00 00 00 00")
    abort = transfer.on_response(h("4B 40 60 00 37 02 00 00"))
    assert abort == h("80 08 10 00 01 00 04 05")
    assert transfer.result == f.SdoResult(abort_code=codes.ABORT_COMMAND)
    transfer = f.SdoClientTransfer(0x6041, 0)
    assert transfer.timeout() == h("80 41 60 00 00 00 04 05")
    assert transfer.result is not None and transfer.result.abort_code == codes.ABORT_TIMEOUT


@given(st.binary(min_size=1, max_size=64))
def test_client_round_trip(value: bytes) -> None:
    server = _Server({})
    assert _run(f.SdoClientTransfer(0x2100, 3, value), server)[0].ok
    assert _run(f.SdoClientTransfer(0x2100, 3), server)[0].data == value


# --- PDO mapping entries ---


def test_mapping_entry_golden() -> None:
    assert f.MappingEntry(0x6040, 0, 16).encode() == 0x60400010
    assert f.MappingEntry.decode(0x606C0020) == f.MappingEntry(0x606C, 0, 32)
    entries = (f.MappingEntry(0x6041, 0, 16), f.MappingEntry(0x6044, 0, 16))
    assert f.unpack_pdo(entries, h("37 02 DC 05")) == (h("37 02"), h("DC 05"))
    with pytest.raises(CanOpenDecodeError):
        f.unpack_pdo(entries, h("37 02"))


def test_can_frame_from_bus() -> None:
    frame = f.CanFrame.from_bus(0x185, bytearray(b"\x01\x02"))
    assert frame == f.CanFrame(0x185, b"\x01\x02")
    assert frame.arbitration_id == 0x185
    for args in ((0x800, b""), (0x100, bytes(9))):
        with pytest.raises(InvalidCobId):
            f.CanFrame.from_bus(*args)
    with pytest.raises(InvalidCobId):
        f.CanFrame.from_bus(0x185, b"", is_extended_id=True)


@given(IDENTIFIERS, DATA, st.booleans())
def test_from_bus_short_cut_is_the_checked_constructor(
    cob_id: object, data: bytes | bytearray, extended: bool
) -> None:
    """``from_bus``'s one-test path for the usual frame against the checked constructor:
    the same frame, or InvalidCobId for what CANopen cannot carry."""
    valid = carried(cob_id, data, extended)
    if not valid:
        with pytest.raises(InvalidCobId):
            f.CanFrame.from_bus(cob_id, data, is_extended_id=extended)  # type: ignore[arg-type]
        return
    assert isinstance(cob_id, int)
    frame = f.CanFrame.from_bus(cob_id, data, is_extended_id=extended)
    assert frame == f.CanFrame(cob_id, bytes(data))
    assert type(frame.data) is bytes and frame.data == bytes(data)
