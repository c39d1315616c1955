"""DP-V0 PDUs (fact sheet 1.4 to 1.9)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.profibus.codec import chkcfg, diag, dp
from adapters.profibus.codec.chkcfg import (
    CompactId,
    Configuration,
    IoDirection,
    IoLength,
    SpecialId,
)
from adapters.profibus.codec.diag import (
    AlarmDiag,
    AlarmSpecifier,
    AlarmType,
    ChannelDiag,
    ChannelDirection,
    ChannelType,
    DeviceDiag,
    IdentifierDiag,
    SlaveDiag,
    StatusDiag,
    StatusType,
)
from adapters.profibus.codec.dp import (
    DataExchange,
    Dpv1Status,
    GetCfgRequest,
    GlobalControl,
    InputData,
    OutputData,
    ReadInputsRequest,
    ReadOutputsRequest,
    SetPrm,
    SetSlaveAdd,
    SlaveDiagRequest,
    SlaveSap,
)
from adapters.profibus.codec.fdl import (
    DataTelegram,
    FcbState,
    RequestFc,
    RequestFunction,
    ResponseFc,
    ResponseStatus,
    decode_telegram,
)
from adapters.profibus.errors import DecodeFailure, DpDecodeError
from gateway.errors import FrameEncodeError

h = bytes.fromhex
FAST = settings(max_examples=50, deadline=None)


def as_data(wire: bytes) -> DataTelegram:
    telegram = decode_telegram(wire)
    assert isinstance(telegram, DataTelegram)
    return telegram


def flag(name: str) -> dict[str, Any]:
    """Keyword arguments setting one boolean field by name."""
    return {name: True}


# --------------------------------------------------------------------------- SAPs


def test_sap_numbers() -> None:
    # fact sheet 1.4 (and the brief): slave SAPs, master SAP 62, MSAC_C1 51
    assert [SlaveSap.SET_PRM, SlaveSap.CHK_CFG, SlaveSap.SLAVE_DIAG, SlaveSap.GET_CFG] == [
        61,
        62,
        60,
        59,
    ]
    assert [SlaveSap.GLOBAL_CONTROL, SlaveSap.SET_SLAVE_ADD] == [58, 55]
    assert [SlaveSap.RD_INP, SlaveSap.RD_OUTP, SlaveSap.MSAC_C1] == [56, 57, 51]
    assert int(dp.MasterSap.MS0) == 62
    assert int(dp.MasterSap.MS1) == 51


# --------------------------------------------------------------------------- Set_Prm

SET_PRM_EXAMPLE = h("88 01 0A 0B 80 B5 00 00 00 00")  # fact sheet 1.6 example (DU)
SET_PRM_FRAME = h("68 0F 0F 68 85 82 5D 3D 3E 88 01 0A 0B 80 B5 00 00 00 00 B2 16")
SET_PRM_PDU = SetPrm(
    ident_number=0x80B5,
    lock_req=True,
    wd_on=True,
    wd_fact_1=1,
    wd_fact_2=10,
    min_tsdr=11,
    dpv1=Dpv1Status(dpv1_enable=False),
)


def test_set_prm_golden_both_directions() -> None:
    assert SetPrm.decode(SET_PRM_EXAMPLE, dpv1=True) == SET_PRM_PDU
    assert SET_PRM_PDU.encode() == SET_PRM_EXAMPLE
    fc = FcbState.reset().acknowledged().fc(RequestFunction.SRD_HIGH)  # 0x5D
    telegram = dp.build_request(SET_PRM_PDU, da=5, sa=2, fc=fc)
    assert telegram.encode() == SET_PRM_FRAME
    assert dp.decode_request(as_data(SET_PRM_FRAME), dpv1=True) == SET_PRM_PDU


def test_set_prm_dpv0_layout_keeps_bytes_7_on_as_user_data() -> None:
    pdu = SetPrm.decode(SET_PRM_EXAMPLE)
    assert pdu.dpv1 is None
    assert pdu.user_prm_data == h("00 00 00")
    assert pdu.encode() == SET_PRM_EXAMPLE


def test_set_prm_station_status_bits() -> None:
    # 1.6 byte 0: b3 WD_On, b4 Freeze_Req, b5 Sync_Req, b6 Unlock_Req, b7 Lock_Req
    cases = {"wd_on": 0x08, "freeze_req": 0x10, "sync_req": 0x20, "unlock_req": 0x40}
    for name, bit in cases.items():
        pdu = SetPrm(0x1234, lock_req=False, **flag(name))
        assert pdu.encode()[0] == bit
        assert SetPrm.decode(pdu.encode()) == pdu
    assert SetPrm(0x1234).encode()[0] == 0x80


def test_dpv1_status_bits() -> None:
    # 1.6 bytes 7-9
    status = Dpv1Status(
        dpv1_enable=True,
        wd_base_1ms=True,
        chk_cfg_mode=True,
        diagnostic_alarm=True,
        pull_plug_alarm=True,
        alarm_mode=7,
        prm_cmd=True,
    )
    assert status.encode() == h("84 A1 87")
    assert Dpv1Status.decode(h("84 A1 87")) == status
    assert status.max_alarms == 32
    assert Dpv1Status(alarm_mode=0).max_alarms == 1


def test_watchdog_factors() -> None:
    assert dp.watchdog_factors(0.1) == (1, 10)  # fact sheet 1.6 example
    assert dp.watchdog_factors(0.01) == (1, 1)
    assert dp.watchdog_factors(0.015) == (1, 2)  # never shorter than asked
    assert dp.watchdog_factors(650.25) == (255, 255)
    assert dp.watchdog_factors(0.1, base_1ms=True) == (1, 100)
    f1, f2 = dp.watchdog_factors(2.57)  # 257 units: prime, so 258 = 2 x 129
    assert (f1, f2) == (2, 129)
    assert dp.watchdog_time(1, 10) == pytest.approx(0.1)
    assert SET_PRM_PDU.watchdog_time == pytest.approx(0.1)
    for bad in (0.0, -1.0, 651.0, float("nan")):
        with pytest.raises(FrameEncodeError):
            dp.watchdog_factors(bad)


@FAST
@given(st.floats(0.001, 650.0))
def test_watchdog_factors_cover_the_time(timeout: float) -> None:
    f1, f2 = dp.watchdog_factors(timeout)
    assert 1 <= f1 <= 255
    assert 1 <= f2 <= 255
    assert dp.watchdog_time(f1, f2) >= timeout - 1e-9
    assert dp.watchdog_time(f1, f2) < max(timeout * 1.01, timeout + 0.0101)


def test_set_prm_errors() -> None:
    with pytest.raises(DpDecodeError) as info:
        SetPrm.decode(h("88 00 0A 0B 80 B5 00"))
    assert info.value.reason is DecodeFailure.BAD_FIELD
    with pytest.raises(DpDecodeError) as info:
        SetPrm.decode(h("88 01 0A 0B 80 B5 00"), dpv1=True)
    assert info.value.reason is DecodeFailure.TRUNCATED
    with pytest.raises(FrameEncodeError):
        SetPrm(0x10000).encode()
    with pytest.raises(FrameEncodeError):
        SetPrm(1, wd_fact_1=0).encode()


# --------------------------------------------------------------------------- Chk_Cfg / Get_Cfg

CFG_GOLDEN = [
    # fact sheet 1.7 examples
    ("F1", (CompactId(IoDirection.INPUT_OUTPUT, 2, words=True, consistent=True),)),
    ("71", (CompactId(IoDirection.INPUT_OUTPUT, 2, words=True),)),
    ("E1", (CompactId(IoDirection.OUTPUT, 2, words=True, consistent=True),)),
    ("D1", (CompactId(IoDirection.INPUT, 2, words=True, consistent=True),)),
    ("13", (CompactId(IoDirection.INPUT, 4),)),
    ("23", (CompactId(IoDirection.OUTPUT, 4),)),
    (
        "C0 C1 C1",
        (SpecialId(output=IoLength(2, True, True), input=IoLength(2, True, True)),),
    ),
    (
        "00 F1",  # MICROMASTER 4 PPO3
        (SpecialId(), CompactId(IoDirection.INPUT_OUTPUT, 2, words=True, consistent=True)),
    ),
    # computed from the 1.7 rules
    ("0F", (SpecialId(skip_check=True),)),
    ("42 BF 01 02", (SpecialId(input=IoLength(64, False, True), manufacturer_data=h("0102")),)),
    ("81 40 AA", (SpecialId(output=IoLength(1, True), manufacturer_data=h("AA")),)),
    ("3F", (CompactId(IoDirection.INPUT_OUTPUT, 16),)),
]


@pytest.mark.parametrize(("wire", "identifiers"), CFG_GOLDEN)
def test_cfg_golden_both_directions(
    wire: str, identifiers: tuple[chkcfg.CfgIdentifier, ...]
) -> None:
    assert chkcfg.decode_identifiers(h(wire)) == identifiers
    assert chkcfg.encode_identifiers(identifiers) == h(wire)


def test_cfg_lengths() -> None:
    config = Configuration.decode(h("F1"))
    assert (config.input_bytes, config.output_bytes) == (4, 4)
    config = Configuration.decode(h("C0 C1 C1 13 23 E1"))
    assert (config.input_bytes, config.output_bytes) == (8, 12)
    assert chkcfg.total_input_bytes(config.identifiers) == 8
    assert chkcfg.total_output_bytes(config.identifiers) == 12


def test_cfg_errors() -> None:
    with pytest.raises(DpDecodeError) as info:
        chkcfg.decode_identifiers(h("C2 C1 C1 01"))  # 2 manufacturer bytes, one present
    assert info.value.reason is DecodeFailure.TRUNCATED
    with pytest.raises(DpDecodeError) as info:
        Configuration.decode(h("0F"), allow_skip_check=False)  # not in Get_Cfg
    assert info.value.reason is DecodeFailure.BAD_FIELD
    with pytest.raises(FrameEncodeError):
        CompactId(IoDirection.INPUT, 17).encode()
    with pytest.raises(FrameEncodeError):
        SpecialId(input=IoLength(65)).encode()
    with pytest.raises(FrameEncodeError):
        SpecialId(manufacturer_data=bytes(15)).encode()
    with pytest.raises(FrameEncodeError):
        SpecialId(skip_check=True, manufacturer_data=b"x").encode()


# --------------------------------------------------------------------------- Slave_Diag

DIAG_GOLDEN = [
    (
        # computed from 1.8: just powered up, not parameterised, no master yet
        "02 05 00 FF 80 B5",
        SlaveDiag(0x80B5, station_not_ready=True, prm_req=True),
    ),
    (
        # computed from 1.8: in data exchange with master 2, watchdog on
        "00 0C 00 02 80 B5",
        SlaveDiag(0x80B5, wd_on=True, master_address=2),
    ),
    (
        # computed from 1.8 + MCD 600 manual 5.1: ext diag, device block length 3
        # (trip code 0x1A, changed parameter 0)
        "08 0C 00 02 12 34 03 1A 00",
        SlaveDiag(
            0x1234, ext_diag=True, wd_on=True, master_address=2, blocks=(DeviceDiag(h("1A00")),)
        ),
    ),
    (
        # computed from 1.8: every status flag set
        "FF BF 80 7E FF FF",
        SlaveDiag(
            0xFFFF,
            station_not_existent=True,
            station_not_ready=True,
            cfg_fault=True,
            ext_diag=True,
            not_supported=True,
            invalid_slave_response=True,
            prm_fault=True,
            master_lock=True,
            prm_req=True,
            stat_diag=True,
            wd_on=True,
            freeze_mode=True,
            sync_mode=True,
            deactivated=True,
            ext_diag_overflow=True,
            master_address=126,
        ),
    ),
    (
        # computed from 1.8: identifier block (modules 0 and 9) + channel block
        # (module 1, channel 3 input, word, overload)
        "08 0C 00 02 12 34 43 01 02 81 43 A4",
        SlaveDiag(
            0x1234,
            ext_diag=True,
            wd_on=True,
            master_address=2,
            blocks=(
                IdentifierDiag(h("0102")),
                ChannelDiag(1, 3, ChannelDirection.INPUT, ChannelType.WORD, 4),
            ),
        ),
    ),
]


@pytest.mark.parametrize(("wire", "diag"), DIAG_GOLDEN)
def test_slave_diag_golden_both_directions(wire: str, diag: SlaveDiag) -> None:
    assert SlaveDiag.decode(h(wire)) == diag
    assert diag.encode() == h(wire)


def test_slave_diag_status_bits_one_by_one() -> None:
    # fact sheet 1.8 bit table: (byte, bit) of every named flag
    layout = {
        "station_not_existent": (0, 0),
        "station_not_ready": (0, 1),
        "cfg_fault": (0, 2),
        "ext_diag": (0, 3),
        "not_supported": (0, 4),
        "invalid_slave_response": (0, 5),
        "prm_fault": (0, 6),
        "master_lock": (0, 7),
        "prm_req": (1, 0),
        "stat_diag": (1, 1),
        "wd_on": (1, 3),
        "freeze_mode": (1, 4),
        "sync_mode": (1, 5),
        "deactivated": (1, 7),
        "ext_diag_overflow": (2, 7),
    }
    base = SlaveDiag(0).encode()
    assert base == h("00 04 00 FF 00 00")  # Status_2 b2 is always 1
    for name, (byte, bit) in layout.items():
        wire = bytearray(base)
        wire[byte] |= 1 << bit
        diag = SlaveDiag.decode(bytes(wire))
        assert getattr(diag, name) is True, name
        assert diag.encode() == bytes(wire)
    assert SlaveDiag.decode(h("00 00 00 FF 00 00")).always_one is False


def test_ready_for_data_exchange() -> None:
    assert not SlaveDiag.decode(h("02 05 00 FF 80 B5")).ready_for_data_exchange
    assert SlaveDiag.decode(h("00 0C 00 02 80 B5")).ready_for_data_exchange
    for name in ("cfg_fault", "prm_fault", "prm_req", "station_not_ready"):
        assert not SlaveDiag(1, **flag(name)).ready_for_data_exchange


def test_dpv1_alarm_and_status_blocks() -> None:
    # computed from 1.8: device block with a diagnostic alarm, slot 1, appears, Add_Ack,
    # sequence 5 (specifier 0b00101_1_01 = 0x2D), 2 data bytes; then a status message
    alarm = AlarmDiag(AlarmType.DIAGNOSTIC, 1, AlarmSpecifier.APPEARS, True, 5, h("BEEF"))
    status = StatusDiag(StatusType.MODULE_STATUS, 0, AlarmSpecifier.NONE, h("55"))
    diag_blocks = h("06 01 01 2D BE EF 05 82 00 00 55")
    assert diag.decode_diag_blocks(diag_blocks, dpv1=True) == (alarm, status)
    assert alarm.encode() + status.encode() == diag_blocks
    # without dpv1 the same bytes are plain device-related blocks
    assert diag.decode_diag_blocks(diag_blocks) == (
        DeviceDiag(h("01 01 2D BE EF")),
        DeviceDiag(h("82 00 00 55")),
    )


def test_identifier_diag_helpers() -> None:
    block = IdentifierDiag.for_modules([0, 9])
    assert block.bitmap == h("0102")
    assert block.faulty_modules == (0, 9)
    assert IdentifierDiag.for_modules([], size=2).bitmap == h("0000")
    with pytest.raises(FrameEncodeError):
        IdentifierDiag.for_modules([16], size=2)


def test_channel_error_texts() -> None:
    block = ChannelDiag(0, 0, ChannelDirection.OUTPUT, ChannelType.BIT, 6)
    assert block.error_text == "wire break"
    assert diag.channel_error_text(20) == "vendor specific"
    assert diag.channel_error_text(12) == "reserved"


def test_extended_diagnosis_in_words() -> None:
    # what a fault text quotes of the slave (1.8 field names and channel error table)
    blocks = (
        DeviceDiag(h("1A 00")),
        IdentifierDiag.for_modules([0, 9]),
        ChannelDiag(1, 3, ChannelDirection.OUTPUT, ChannelType.WORD, 20),
        AlarmDiag(AlarmType.PULL, 2, AlarmSpecifier.DISAPPEARS, data=h("0102")),
        StatusDiag(StatusType.MODULE_STATUS, 4),
        AlarmDiag(99, 1),
    )
    assert diag.describe_blocks(blocks).split("; ") == [
        "device diagnosis 1A 00",
        "module(s) 0, 9 report a fault",
        "module 1 channel 3 (output, word): vendor specific (error 20)",
        "pull alarm, slot 2, disappears 01 02",
        "module status message, slot 4",
        "type 99 alarm, slot 1, appears",
    ]
    assert diag.describe_blocks(()) == ""
    assert diag.describe_blocks([IdentifierDiag(h("00"))]) == "no module reports a fault"


@pytest.mark.parametrize(
    ("wire", "reason"),
    [
        ("00 04 00 FF 00", DecodeFailure.TRUNCATED),
        ("08 04 00 FF 00 00 05 01", DecodeFailure.BAD_LENGTH),  # block longer than data
        ("08 04 00 FF 00 00 00", DecodeFailure.BAD_LENGTH),  # block length 0
        ("08 04 00 FF 00 00 81 01", DecodeFailure.TRUNCATED),  # channel block cut
        ("08 04 00 FF 00 00 C3 00 00", DecodeFailure.UNSUPPORTED),  # header type 11
    ],
)
def test_slave_diag_errors(wire: str, reason: DecodeFailure) -> None:
    with pytest.raises(DpDecodeError) as info:
        SlaveDiag.decode(h(wire))
    assert info.value.reason is reason
    assert info.value.raw


# --------------------------------------------------------------------------- Global_Control


def test_global_control_golden() -> None:
    frame = h("68 07 07 68 FF 82 46 3A 3E 00 00 3F 16")  # fact sheet 1.9 example
    telegram = dp.global_control_request(GlobalControl.operate(), sa=2)
    assert telegram.encode() == frame
    assert dp.decode_request(as_data(frame)) == GlobalControl()
    assert GlobalControl.clear().encode() == h("02 00")  # profirust's Clear


@pytest.mark.parametrize(
    ("wire", "pdu"),
    [
        ("02 00", GlobalControl(clear_data=True)),
        ("04 00", GlobalControl(unfreeze=True)),
        ("08 00", GlobalControl(freeze=True)),
        ("10 00", GlobalControl(unsync=True)),
        ("20 01", GlobalControl(sync=True, group_select=1)),
        ("3E 81", GlobalControl(True, True, True, True, True, 0x81)),
    ],
)
def test_global_control_bits(wire: str, pdu: GlobalControl) -> None:
    assert GlobalControl.decode(h(wire)) == pdu
    assert pdu.encode() == h(wire)


def test_global_control_groups() -> None:
    assert GlobalControl.groups_mask([1, 8]) == 0x81
    with pytest.raises(FrameEncodeError):
        GlobalControl.groups_mask([0])
    with pytest.raises(DpDecodeError):
        GlobalControl.decode(h("00"))


# --------------------------------------------------------------------------- telegram level


def test_data_exchange_golden() -> None:
    frame = h("68 07 07 68 05 02 5D 04 7F 20 00 07 16")  # fact sheet 1.2 example
    fc = FcbState.reset().acknowledged().fc(RequestFunction.SRD_HIGH)
    telegram = dp.build_request(DataExchange(h("04 7F 20 00")), da=5, sa=2, fc=fc)
    assert telegram.encode() == frame
    assert dp.decode_request(as_data(frame)) == DataExchange(h("047F2000"))


def test_first_slave_diag_golden() -> None:
    frame = h("68 05 05 68 85 82 6D 3C 3E EE 16")  # fact sheet 1.2 example
    fc = FcbState.reset().fc(RequestFunction.SRD_HIGH)
    assert dp.build_request(SlaveDiagRequest(), da=5, sa=2, fc=fc).encode() == frame
    assert dp.decode_request(as_data(frame)) == SlaveDiagRequest()


REQUESTS: list[tuple[dp.DpRequest, int | None, RequestFunction]] = [
    (DataExchange(b"\x01\x02"), None, RequestFunction.SRD_HIGH),
    (SetSlaveAdd(7, 0x80B5, True, b"u"), 55, RequestFunction.SRD_HIGH),
    (ReadInputsRequest(), 56, RequestFunction.SRD_HIGH),
    (ReadOutputsRequest(), 57, RequestFunction.SRD_HIGH),
    (GlobalControl(freeze=True), 58, RequestFunction.SDN_HIGH),
    (GetCfgRequest(), 59, RequestFunction.SRD_HIGH),
    (SlaveDiagRequest(), 60, RequestFunction.SRD_HIGH),
    (SetPrm(0x80B5, user_prm_data=b"\x01"), 61, RequestFunction.SRD_HIGH),
    (Configuration(Configuration.decode(h("F1")).identifiers), 62, RequestFunction.SRD_HIGH),
]


@pytest.mark.parametrize(("pdu", "sap", "function"), REQUESTS)
def test_request_dispatch(pdu: dp.DpRequest, sap: int | None, function: RequestFunction) -> None:
    telegram = dp.build_request(pdu, da=5, sa=2)
    assert telegram.dsap == sap
    assert telegram.ssap == (None if sap is None else 62)
    assert telegram.fc == RequestFc(function)
    assert dp.decode_request(as_data(telegram.encode())) == pdu


RESPONSES: list[tuple[dp.DpResponse, int | None, int | None]] = [
    (InputData(h("01 02 03 04")), None, None),
    (InputData(h("AA")), 56, 62),
    (OutputData(h("BB")), 57, 62),
    (Configuration.decode(h("F1")), 59, 62),
    (SlaveDiag(0x80B5, master_address=2), 60, 62),
]


@pytest.mark.parametrize(("pdu", "dsap", "ssap"), RESPONSES)
def test_response_dispatch(pdu: dp.DpResponse, dsap: int | None, ssap: int | None) -> None:
    request = DataTelegram(5, 2, RequestFc(RequestFunction.SRD_HIGH), dsap, ssap)
    reply = dp.build_response(pdu, request=request)
    assert (reply.da, reply.sa) == (2, 5)
    assert (reply.dsap, reply.ssap) == (ssap, dsap)  # SAPs swapped
    assert reply.fc == ResponseFc(ResponseStatus.DL)
    assert dp.decode_response(as_data(reply.encode())) == pdu


def test_dispatch_errors() -> None:
    with pytest.raises(DpDecodeError) as info:
        dp.decode_request(DataTelegram(5, 2, RequestFc(RequestFunction.SRD_HIGH), 20, 62))
    assert info.value.reason is DecodeFailure.UNKNOWN_FUNCTION
    with pytest.raises(DpDecodeError):  # a response is no request
        dp.decode_request(DataTelegram(5, 2, ResponseFc(ResponseStatus.DL), 60, 62))
    with pytest.raises(DpDecodeError):
        dp.decode_response(DataTelegram(2, 5, RequestFc(RequestFunction.SRD_HIGH)))
    with pytest.raises(DpDecodeError):
        dp.decode_response(DataTelegram(2, 5, ResponseFc(ResponseStatus.DL), 62, 61))
    with pytest.raises(DpDecodeError):  # Get_Cfg reply must not use nibble 15
        dp.decode_response(DataTelegram(2, 5, ResponseFc(ResponseStatus.DL), 62, 59, h("0F")))
    with pytest.raises(DpDecodeError):  # empty requests carry no data
        dp.decode_request(DataTelegram(5, 2, RequestFc(RequestFunction.SRD_HIGH), 60, 62, b"x"))
    with pytest.raises(FrameEncodeError):
        dp.build_request("nonsense", da=5, sa=2)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- round trips

bools = st.booleans()
u8 = st.integers(0, 255)
u16 = st.integers(0, 0xFFFF)

dpv1_statuses = st.builds(
    Dpv1Status,
    *[bools] * 13,
    alarm_mode=st.integers(0, 7),
    prm_structure=bools,
    isom_req=bools,
    prm_cmd=bools,
)


@st.composite
def set_prms(draw: st.DrawFn) -> SetPrm:
    dpv1 = draw(st.none() | dpv1_statuses)
    room = 244 - 7 - (3 if dpv1 else 0)
    lock, unlock, sync, freeze, wd_on = draw(st.tuples(*[bools] * 5))
    return SetPrm(
        draw(u16),
        lock_req=lock,
        unlock_req=unlock,
        sync_req=sync,
        freeze_req=freeze,
        wd_on=wd_on,
        wd_fact_1=draw(st.integers(1, 255)),
        wd_fact_2=draw(st.integers(1, 255)),
        min_tsdr=draw(u8),
        group_ident=draw(u8),
        dpv1=dpv1,
        user_prm_data=draw(st.binary(max_size=room) | st.binary(max_size=8)),
    )


io_lengths = st.builds(IoLength, st.integers(1, 64), bools, bools)
compact_ids = st.builds(CompactId, st.sampled_from(IoDirection), st.integers(1, 16), bools, bools)
special_ids = st.builds(
    SpecialId, st.none() | io_lengths, st.none() | io_lengths, st.binary(max_size=14)
) | st.builds(SpecialId, st.none() | io_lengths, st.none() | io_lengths, skip_check=st.just(True))
identifiers = st.lists(compact_ids | special_ids, max_size=12).map(tuple)

slots = u8
diag_blocks = st.one_of(
    st.builds(DeviceDiag, st.binary(max_size=62)),
    st.builds(IdentifierDiag, st.binary(max_size=62)),
    st.builds(
        ChannelDiag,
        st.integers(0, 63),
        st.integers(0, 63),
        st.sampled_from(ChannelDirection),
        st.sampled_from(ChannelType),
        st.integers(0, 31),
    ),
)
dpv1_blocks = st.one_of(
    st.builds(
        AlarmDiag,
        st.integers(0, 127),
        slots,
        st.sampled_from(AlarmSpecifier),
        bools,
        st.integers(0, 31),
        st.binary(max_size=59),
    ),
    st.builds(
        StatusDiag,
        st.integers(0, 127),
        slots,
        st.sampled_from(AlarmSpecifier),
        st.binary(max_size=59),
    ),
    st.builds(DeviceDiag, st.binary(max_size=2)),  # too short for alarm/status
    diag_blocks.filter(lambda b: not isinstance(b, DeviceDiag)),
)


def slave_diags(blocks: st.SearchStrategy[diag.DiagBlock]) -> st.SearchStrategy[SlaveDiag]:
    return st.builds(
        SlaveDiag,
        u16,
        *[bools] * 16,
        master_address=u8,
        blocks=st.lists(blocks, max_size=3).map(tuple),
    )


@FAST
@given(set_prms())
def test_set_prm_round_trip(pdu: SetPrm) -> None:
    assert SetPrm.decode(pdu.encode(), dpv1=pdu.dpv1 is not None) == pdu


@FAST
@given(identifiers)
def test_cfg_round_trip(ids: tuple[chkcfg.CfgIdentifier, ...]) -> None:
    assert Configuration.decode(Configuration(ids).encode()) == Configuration(ids)


@FAST
@given(slave_diags(diag_blocks))
def test_slave_diag_round_trip(diag: SlaveDiag) -> None:
    assert SlaveDiag.decode(diag.encode()) == diag


@FAST
@given(slave_diags(dpv1_blocks))
def test_slave_diag_dpv1_round_trip(diag: SlaveDiag) -> None:
    assert SlaveDiag.decode(diag.encode(), dpv1=True) == diag


@FAST
@given(st.builds(GlobalControl, bools, bools, bools, bools, bools, u8))
def test_global_control_round_trip(pdu: GlobalControl) -> None:
    assert GlobalControl.decode(pdu.encode()) == pdu


@FAST
@given(st.builds(SetSlaveAdd, st.integers(0, 127), u16, bools, st.binary(max_size=20)))
def test_set_slave_add_round_trip(pdu: SetSlaveAdd) -> None:
    assert SetSlaveAdd.decode(pdu.encode()) == pdu


@FAST
@given(st.binary(max_size=246), st.binary(max_size=244))
def test_io_data_round_trip(data: bytes, short: bytes) -> None:
    assert DataExchange.decode(DataExchange(data).encode()) == DataExchange(data)
    assert InputData.decode(InputData(data).encode()) == InputData(data)
    assert OutputData.decode(OutputData(short).encode()) == OutputData(short)


dp_requests = st.one_of(
    set_prms(),
    identifiers.map(Configuration),
    st.builds(GlobalControl, bools, bools, bools, bools, bools, u8),
    st.builds(SetSlaveAdd, st.integers(0, 127), u16, bools, st.binary(max_size=20)),
    st.builds(DataExchange, st.binary(max_size=246)),
    st.sampled_from(
        [SlaveDiagRequest(), GetCfgRequest(), ReadInputsRequest(), ReadOutputsRequest()]
    ),
)
dp_responses = st.one_of(
    st.builds(InputData, st.binary(max_size=244)),
    st.builds(OutputData, st.binary(max_size=244)),
    identifiers.filter(lambda ids: not any(getattr(i, "skip_check", False) for i in ids)).map(
        Configuration
    ),
    slave_diags(diag_blocks),
)


@FAST
@given(dp_requests, st.integers(0, 126), st.integers(0, 126))
def test_request_telegram_round_trip(pdu: dp.DpRequest, da: int, sa: int) -> None:
    telegram = dp.build_request(pdu, da=da, sa=sa)
    dpv1_layout = isinstance(pdu, SetPrm) and pdu.dpv1 is not None
    assert dp.decode_request(as_data(telegram.encode()), dpv1=dpv1_layout) == pdu


@FAST
@given(dp_responses)
def test_response_telegram_round_trip(pdu: dp.DpResponse) -> None:
    sap = {InputData: 56, OutputData: 57, Configuration: 59, SlaveDiag: 60}[type(pdu)]
    request = DataTelegram(5, 2, RequestFc(RequestFunction.SRD_HIGH), sap, 62)
    reply = dp.build_response(pdu, request=request)
    assert dp.decode_response(as_data(reply.encode())) == pdu


DECODERS: list[Callable[[bytes], object]] = [
    SetPrm.decode,
    lambda b: SetPrm.decode(b, dpv1=True),
    Configuration.decode,
    lambda b: Configuration.decode(b, allow_skip_check=False),
    SlaveDiag.decode,
    lambda b: SlaveDiag.decode(b, dpv1=True),
    GlobalControl.decode,
    SetSlaveAdd.decode,
    SlaveDiagRequest.decode,
    Dpv1Status.decode,
]


@settings(max_examples=40, deadline=None)
@given(st.binary(max_size=40))
def test_decoders_raise_only_typed_errors(raw: bytes) -> None:
    for decode in DECODERS:
        try:
            decode(raw)
        except DpDecodeError as exc:
            assert exc.raw == raw
