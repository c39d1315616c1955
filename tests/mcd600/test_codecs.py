"""Monitoring, programming, diagnosis and layout codecs (guide 4.1, 4.3, 4.4, 5.1)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.mcd600.diag import ExtDiag
from adapters.mcd600.errors import Mcd600DecodeError
from adapters.mcd600.layout import LAYOUTS, InputTelegram, Mode, OutputTelegram
from adapters.mcd600.monitoring import (
    DataRequest,
    MonitorReply,
    PowerScale,
    ScaledPower,
    StarterState,
    StarterStateWord,
    decode_value,
)
from adapters.mcd600.programming import IDLE, ParamReply, ParamRequest
from adapters.mcd600.words import ControlWord, MotorSet, StatusWord
from gateway.errors import FrameDecodeError, FrameEncodeError

# ------------------------------------------------------------------ layout (4.1)


@pytest.mark.parametrize(
    ("mode", "cfg", "out_len", "in_len"),
    [
        (Mode.BASIC, "F0", 2, 2),
        (Mode.EXTENDED, "F0 A0 93", 3, 6),
        (Mode.PARAMETER, "F0 A0 93 B3", 7, 10),
    ],
)
def test_mode_layouts(mode: Mode, cfg: str, out_len: int, in_len: int) -> None:
    layout = LAYOUTS[mode]
    assert layout.cfg == bytes.fromhex(cfg)
    assert (layout.output_len, layout.input_len) == (out_len, in_len)


def _cfg_lengths(cfg: bytes) -> tuple[int, int]:
    """Independent reading of compact identifiers (fact sheet 1.7): (outputs, inputs)."""
    out = inp = 0
    for byte in cfg:
        size = ((byte & 0x0F) + 1) * (2 if byte & 0x40 else 1)
        assert byte & 0x80, "consistent"
        if byte & 0x20:
            out += size
        if byte & 0x10:
            inp += size
    return out, inp


@pytest.mark.parametrize("mode", list(Mode))
def test_cfg_bytes_match_the_lengths(mode: Mode) -> None:
    layout = LAYOUTS[mode]
    assert _cfg_lengths(layout.cfg) == (layout.output_len, layout.input_len)


def test_parameter_mode_outputs_golden() -> None:
    # start (4.2), data request 4 in byte 2 (4.3 t4), read parameter 7 in bytes 3-6 (4.4.1 t7)
    tel = OutputTelegram(ControlWord(start=True), 4, ParamRequest(7, read=True))
    assert tel.encode(LAYOUTS[Mode.PARAMETER]) == bytes.fromhex("00 01 04 07 02 00 00")
    write = OutputTelegram(ControlWord(), 1, ParamRequest(9, write=True, value=0x0123))
    assert write.encode(LAYOUTS[Mode.PARAMETER]) == bytes.fromhex("00 00 01 09 04 01 23")
    assert OutputTelegram(ControlWord(start=True), 4).encode(LAYOUTS[Mode.EXTENDED]) == (
        bytes.fromhex("00 01 04")
    )
    assert OutputTelegram(ControlWord(start=True), 4).encode(LAYOUTS[Mode.BASIC]) == (
        bytes.fromhex("00 01")
    )


def test_parameter_mode_inputs_golden() -> None:
    # status 4.2 t3, monitoring echo 4 value 0x0021 (4.3 t5), parameter echo 7 value 350 (t8)
    wire = bytes.fromhex("60 02 04 00 00 21 07 00 01 5E")
    tel = InputTelegram.decode(LAYOUTS[Mode.PARAMETER], wire)
    assert tel.status == StatusWord(32, network_control=True, active=True)
    assert tel.monitor == MonitorReply(4, False, 0x21)
    assert tel.param == ParamReply(7, value=350)
    assert tel.encode(LAYOUTS[Mode.PARAMETER]) == wire


def test_inputs_of_the_wrong_length_are_typed_errors() -> None:
    with pytest.raises(Mcd600DecodeError) as info:
        InputTelegram.decode(LAYOUTS[Mode.EXTENDED], bytes(2))
    assert info.value.raw == bytes(2)
    with pytest.raises(FrameDecodeError):
        OutputTelegram.decode(LAYOUTS[Mode.BASIC], bytes(3))


outputs = st.builds(
    OutputTelegram,
    control=st.builds(
        ControlWord,
        start=st.booleans(),
        quick_stop=st.booleans(),
        reset=st.booleans(),
        motor_set=st.sampled_from(MotorSet),
    ),
    request=st.integers(0, 255),
    param=st.builds(
        ParamRequest,
        number=st.integers(0, 255),
        read=st.booleans(),
        write=st.booleans(),
        value=st.integers(0, 0xFFFF),
    ),
)


@settings(max_examples=100, deadline=None)
@given(outputs)
def test_output_telegram_round_trip(tel: OutputTelegram) -> None:
    layout = LAYOUTS[Mode.PARAMETER]
    assert OutputTelegram.decode(layout, tel.encode(layout)) == tel


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(list(Mode)), st.binary(max_size=12))
def test_telegram_decoders_raise_only_typed_errors(mode: Mode, data: bytes) -> None:
    layout = LAYOUTS[mode]
    for decode, size in (
        (InputTelegram.decode, layout.input_len),
        (OutputTelegram.decode, layout.output_len),
    ):
        try:
            tel = decode(layout, data)
        except FrameDecodeError as exc:
            assert len(data) != size
            assert exc.raw == data
        else:
            assert len(data) == size
            if isinstance(tel, InputTelegram):
                again = InputTelegram.decode(layout, tel.encode(layout))
                assert again == tel


# ------------------------------------------------------------------ monitoring (4.3)


def test_monitor_reply_golden() -> None:
    assert MonitorReply.decode(bytes.fromhex("03 00 01 2C")) == MonitorReply(3, False, 300)
    assert MonitorReply.decode(bytes.fromhex("11 01 00 00")) == MonitorReply(17, True, 0)
    assert MonitorReply(2, False, 0x0643).encode() == bytes.fromhex("02 00 06 43")


def test_starter_state_word_golden() -> None:
    # 4.3 t6 request 2: running (3), positive sequence, initialised, trip code 0
    word = StarterStateWord.decode(0x0053)
    assert word == StarterStateWord(3, True, False, True, False, 0)
    assert StarterState(word.state) is StarterState.RUNNING
    tripped = StarterStateWord(6, True, True, True, False, 2)
    assert tripped.encode() == 0x0276
    assert decode_value(DataRequest.STARTER_STATE, 0x0276) == {
        "starter_state": 6,
        "current_above_flc": 1,
        "initialised": 1,
        "card_comm_error": 0,
        "trip_code": 2,
        "phase_sequence": 1,
    }
    # bit 4 is only valid when bit 6 says initialised
    assert "phase_sequence" not in decode_value(DataRequest.STARTER_STATE, 0x0011)


@pytest.mark.parametrize(
    ("value", "kw"),
    [
        (0x0000 | 1234, 12.34),  # scale 0: x 10 W
        (0x1000 | 1234, 123.4),  # scale 1: x 100 W
        (0x2000 | 1234, 1234.0),  # scale 2: kW
        (0x3000 | 1234, 12340.0),  # scale 3: x 10 kW
    ],
)
def test_power_scales(value: int, kw: float) -> None:
    assert decode_value(DataRequest.POWER_KW, value)["power_kw"] == pytest.approx(kw)
    assert decode_value(DataRequest.POWER_KVA, value)["apparent_power_kva"] == pytest.approx(kw)


def test_power_scale_undefined_nibble_is_a_decode_error() -> None:
    with pytest.raises(Mcd600DecodeError):
        decode_value(DataRequest.POWER_KW, 0x4001)


def test_power_encoding_picks_the_finest_scale() -> None:
    assert ScaledPower.from_units(38_060.0) == ScaledPower(3806, PowerScale.TENS)
    assert ScaledPower.from_units(41_000.0) == ScaledPower(410, PowerScale.HUNDREDS)
    assert ScaledPower.from_units(500_000.0) == ScaledPower(500, PowerScale.KILO)
    assert ScaledPower.from_units(5_000_000.0) == ScaledPower(500, PowerScale.TEN_KILO)
    with pytest.raises(FrameEncodeError):
        ScaledPower.from_units(1e9)


def test_other_values() -> None:
    assert decode_value(DataRequest.PRODUCT, 0x0F00) == {"product_type": 15}
    assert decode_value(DataRequest.MOTOR_CURRENT, 0x0123) == {"current_avg_a": 291.0}
    assert decode_value(DataRequest.MOTOR_CURRENT, 650, 0.1) == {
        "current_avg_a": pytest.approx(65.0)
    }
    assert decode_value(DataRequest.MOTOR_TEMPERATURE, 0xFF2A) == {"motor_temp_pct": 42.0}
    assert decode_value(DataRequest.POWER_FACTOR, 85) == {"power_factor": 0.85}
    assert decode_value(DataRequest.VOLTAGE, 0xC190) == {"voltage_v": 400.0}  # bits 14-15 off
    assert decode_value(DataRequest.CURRENT_L2, 0x4041) == {"current_l2_a": 65.0}
    assert decode_value(DataRequest.VOLTAGE_L3, 401) == {"voltage_l3_v": 401.0}
    assert decode_value(DataRequest.VERSION, 0x0104) == {
        "software_version_major": 1,
        "software_version_minor": 4,
    }
    assert decode_value(DataRequest.DIGITAL_INPUTS, 0b11101) == {
        "input_start_stop": 1,
        "input_reset": 1,
        "input_a": 1,
        "input_b": 1,
    }


# ------------------------------------------------------------------ programming (4.4)


def test_param_request_and_reply_golden() -> None:
    assert ParamRequest(1, read=True).encode() == bytes.fromhex("01 02 00 00")
    assert ParamRequest(6, write=True, value=400).encode() == bytes.fromhex("06 04 01 90")
    assert IDLE.encode() == bytes(4)
    assert ParamReply.decode(bytes.fromhex("06 00 01 90")) == ParamReply(6, value=400)
    assert ParamReply.decode(bytes.fromhex("C8 01 00 00")) == ParamReply(200, True, False, 0)
    assert ParamReply.decode(bytes.fromhex("06 02 01 5E")) == ParamReply(6, False, True, 350)


@settings(max_examples=100, deadline=None)
@given(st.binary(min_size=4, max_size=4))
def test_param_codecs_round_trip_the_defined_bits(data: bytes) -> None:
    reply = ParamReply.decode(data)
    assert reply.encode() == bytes((data[0], data[1] & 0x03, data[2], data[3]))
    request = ParamRequest.decode(data)
    assert request.encode() == bytes((data[0], data[1] & 0x06, data[2], data[3]))


# ------------------------------------------------------------------ diagnosis (5.1)


def test_ext_diag_golden() -> None:
    assert ExtDiag(2, 0).encode() == bytes.fromhex("03 02 00")
    assert ExtDiag.decode(bytes.fromhex("03 02 00")) == ExtDiag(2, 0)
    assert ExtDiag.decode(bytes.fromhex("00 05")) == ExtDiag(0, 5)  # without the length byte


@pytest.mark.parametrize("data", ["", "03", "04 02 00", "03 02 00 00", "02 00 00"])
def test_ext_diag_bad_lengths(data: str) -> None:
    with pytest.raises(Mcd600DecodeError):
        ExtDiag.decode(bytes.fromhex(data))


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 255), st.integers(0, 255))
def test_ext_diag_round_trip(trip: int, param: int) -> None:
    assert ExtDiag.decode(ExtDiag(trip, param).encode()) == ExtDiag(trip, param)
