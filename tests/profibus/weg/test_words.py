"""Cyclic words and scales, golden values from the manuals' own examples."""

from __future__ import annotations

import pytest

from adapters.profibus.weg import words as w
from adapters.profibus.weg.spec import CFW11, CFW320, CFW700, scaled
from gateway.errors import FrameEncodeError

# ----------------------------------------------------------------- 13-bit speed


def test_p0681_example_2048_is_450_rpm_at_1800_rpm_synchronous() -> None:
    # CFW-11 P0681 / CFW700 P0681: 8192 -> 1800 rpm, 2048 -> 450 rpm
    assert w.raw_to_speed(2048, 1800.0, w.SPEED_13BIT_BASE) == 450.0
    assert w.raw_to_speed(0x2000, 1800.0, w.SPEED_13BIT_BASE) == 1800.0


def test_p0685_example_900_rpm_is_4096() -> None:
    # CFW-11 P0685: "Referência em 13 bit = 4096 (valor correspondente a 900 rpm)"
    assert w.speed_to_raw(900.0, 1800.0, w.SPEED_13BIT_BASE) == 4096


def test_profidrive_example_2048_is_225_rpm_at_p0134_1800() -> None:
    # CFW-11 P0741 "Velocidade para o perfil PROFIdrive": 4000h = P0134; 2048 -> 225 rpm
    assert w.raw_to_speed(2048, 1800.0, w.PROFIDRIVE_SPEED_BASE) == 225.0
    assert w.speed_to_raw(1800.0, 1800.0, w.PROFIDRIVE_SPEED_BASE) == 0x4000


def test_cfw320_examples_in_hz() -> None:
    # CFW320 P681: 2048 at 60 Hz rated -> 15 Hz; P685: 30 Hz -> 4096
    assert w.raw_to_speed(2048, 60.0, w.SPEED_13BIT_BASE) == 15.0
    assert w.speed_to_raw(30.0, 60.0, w.SPEED_13BIT_BASE) == 4096


def test_scale_saturates_at_four_times_the_base() -> None:
    # CFW320 P681/P685 note: "maximum of 4 times ..., with saturation in 32767 (or -32768)"
    assert w.speed_to_raw(300.0, 60.0, w.SPEED_13BIT_BASE) == 32767
    assert w.speed_to_raw(-300.0, 60.0, w.SPEED_13BIT_BASE) == -32768
    assert w.speed_to_raw(4 * 60.0 - 0.01, 60.0, w.SPEED_13BIT_BASE) == 32767


def test_speed_base_must_be_positive() -> None:
    with pytest.raises(FrameEncodeError):
        w.speed_to_raw(10.0, 0.0, w.SPEED_13BIT_BASE)


@pytest.mark.parametrize(
    ("hz", "rpm", "sync"),
    [(60, 1750, 1800), (60, 1800, 1800), (50, 1450, 1500), (60, 3500, 3600), (60, 1160, 1200)],
)
def test_synchronous_speed_from_rated_frequency_and_speed(hz: int, rpm: int, sync: int) -> None:
    assert w.synchronous_rpm(hz, rpm) == sync


def test_synchronous_speed_needs_positive_ratings() -> None:
    with pytest.raises(ValueError):
        w.synchronous_rpm(0, 1750)


# ----------------------------------------------------------------- direction, P0685


@pytest.mark.parametrize(
    ("bit2", "reference", "effective"),
    [
        (True, 4096, 4096),  # bit 2 = 1 and P0685 > 0: forward
        (True, -4096, -4096),  # bit 2 = 1 and P0685 < 0: reverse
        (False, 4096, -4096),  # bit 2 = 0 and P0685 > 0: reverse
        (False, -4096, 4096),  # bit 2 = 0 and P0685 < 0: forward
    ],
)
def test_the_four_direction_cases_of_p0685(bit2: bool, reference: int, effective: int) -> None:
    assert w.effective_reference(bit2, reference) == effective


# ----------------------------------------------------------------- words on the wire


def test_signed_words() -> None:
    assert w.to_word(-1) == 0xFFFF
    assert w.signed(0xF000) == -4096
    assert w.signed(w.to_word(-32768)) == -32768
    with pytest.raises(FrameEncodeError):
        w.to_word(70000)


def test_manufacturer_control_word_bits() -> None:
    # Table 3.3: run (0) + general enable (1) + direction (2) + remote (4) = 0017h
    run = w.ManufacturerControl(run=True, general_enable=True, forward=True, remote=True)
    assert run.encode(CFW11.control_bits) == 0x0017
    assert w.ManufacturerControl(quick_stop=True).encode(CFW11.control_bits) == 0x0040
    assert w.ManufacturerControl(fault_reset=True).encode(CFW11.control_bits) == 0x0080
    assert w.ManufacturerControl(second_ramp=True, jog=True).encode(CFW700.control_bits) == 0x0028


def test_cfw320_control_word_has_no_quick_stop_bit() -> None:
    # CFW320 Table 4.3: bit 6 reserved
    assert w.ManufacturerControl(quick_stop=True).encode(CFW320.control_bits) == 0
    assert w.ManufacturerControl.decode(0x00FF, CFW320.control_bits).quick_stop is False
    assert w.ManufacturerControl.decode(0x00FF, CFW11.control_bits).quick_stop is True


def test_status_word_bits_per_model() -> None:
    # Table 3.2: bit 8 running, 9 general enable, 10 forward, 12 remote
    s = w.ManufacturerStatus.decode(0x1700, CFW11.status_bits)
    assert (s.running, s.general_enable, s.forward, s.remote, s.fault) == (
        True,
        True,
        True,
        True,
        False,
    )
    assert w.ManufacturerStatus.decode(0x8000, CFW700.status_bits).fault
    # CFW-11 bit 14 is PID automatic; reserved on the CFW700
    assert w.ManufacturerStatus.decode(0x4000, CFW11.status_bits).automatic
    assert not w.ManufacturerStatus.decode(0x4000, CFW700.status_bits).automatic
    # CFW320 bit 1 run command, bit 2 fire mode; bit 4 reserved (no quick stop)
    c = w.ManufacturerStatus.decode(0x0016, CFW320.status_bits)
    assert (c.run_command, c.fire_mode, c.quick_stop_active) == (True, True, False)
    assert w.ManufacturerStatus.decode(0x0010, CFW11.status_bits).quick_stop_active
    assert not w.ManufacturerStatus.decode(0x0006, CFW11.status_bits).run_command


def test_stw1_words_of_the_switching_on_walk() -> None:
    # fact sheet 1.11: 047Eh / 047Fh / 04FEh, with WEG's reserved bit 5 cleared (Table 3.8)
    ready = w.ProfidriveControl(
        no_coast_stop=True,
        no_quick_stop=True,
        enable_operation=True,
        enable_ramp=True,
        enable_setpoint=True,
        control_by_plc=True,
    )
    assert ready.encode(w.STW1_BITS) == 0x045E
    on = w.ProfidriveControl.decode(0x045F, w.STW1_BITS)
    assert on.on and on.enable_operation and on.control_by_plc
    ack = w.ProfidriveControl.decode(0x04DE, w.STW1_BITS)
    assert ack.fault_ack and not ack.on
    assert w.ProfidriveControl.decode(0x047F, w.STW1_BITS).encode(w.STW1_BITS) == 0x045F


@pytest.mark.parametrize(
    ("word", "state"),
    [
        (0x0040, w.ProfidriveState.SWITCHING_ON_INHIBITED),
        (0x0231, w.ProfidriveState.READY_TO_SWITCH_ON),
        (0x0233, w.ProfidriveState.SWITCHED_ON),
        (0x0237, w.ProfidriveState.OPERATION),
        (0x0008, w.ProfidriveState.FAULT),
        (0x0000, w.ProfidriveState.NOT_READY),
    ],
)
def test_zsw1_states(word: int, state: w.ProfidriveState) -> None:
    assert w.ProfidriveStatus.decode(word, CFW11.zsw1_bits).state is state


def test_zsw1_bit_10_frequency_reached_is_cfw11_only() -> None:
    # CFW-11 Table 3.9 bit 10; CFW700 Table 4.8: bits 10 to 15 reserved
    assert w.ProfidriveStatus.decode(0x0400, CFW11.zsw1_bits).frequency_reached
    assert not w.ProfidriveStatus.decode(0x0400, CFW700.zsw1_bits).frequency_reached


def test_namur_bits() -> None:
    # CFW-11 Table 3.7: bit 2 DC link overvoltage (F0022); bit 4 three faults
    assert w.namur_categories(0x0004) == (("DC link overvoltage", (22,)),)
    assert w.namur_categories(0x0010) == (("inverter overtemperature", (51, 54, 57)),)
    assert w.namur_categories(0x0002) == ()  # bit 1 "não implementado"


def test_parameters_have_no_decimal_point_on_the_wire() -> None:
    # P0742: P0003 = 4.7 A is sent as 47; P0750: P0100 = 5.0 s is sent as 50
    assert scaled(3, 47) == 4.7
    assert scaled(100, 50) == 5.0
    assert scaled(2, 1200) == 1200
    assert scaled(685, 0xF000) == -4096


def test_names_follow_each_manual() -> None:
    assert CFW11.pname(3) == "P0003"
    assert CFW320.pname(3) == "P003"
    assert CFW11.fault_text(239) == "Profibus DP interface offline"
    assert CFW320.fault_text(32) == "Comm. plug-in module communication lost"
    assert CFW700.fault_text(71) == "F071"  # not in the CFW700 manual: shown as its code
    assert CFW11.fault_text(71) == "motor overload"  # CFW-11 Table 3.7
    assert CFW320.alarm_text(140) == "A140"  # the CFW320 has no A140
    assert CFW11.comm_status_text(5) == "clear mode"
