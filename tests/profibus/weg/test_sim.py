"""The simulated drives on their own: DP start-up, addresses, status bits, sources, faults."""

from __future__ import annotations

import struct

import pytest

from adapters.profibus.weg.sim import params as sp
from adapters.profibus.weg.sim.dataprofile import PdState
from adapters.profibus.weg.sim.drive import Cfw11Sim, Cfw320Sim, Cfw700Sim, WegSim
from adapters.profibus.weg.spec import DataProfile

NET = {**sp.NETWORK_SOURCES, 100: 20, 101: 20, 102: 5, 103: 5}
RUN_FWD = 0x0017  # run + general enable + bit 2 + remote (Table 3.3)


def exchange(sim: WegSim, now: float, *words: int) -> tuple[int, ...]:
    data = sim.exchange(struct.pack(f">{len(words)}H", *words), now)
    return struct.unpack(f">{len(data) // 2}H", data)


def state(sim: WegSim) -> PdState:
    """The simulator's PROFIdrive state, read through a call (it changes under mypy's eyes)."""
    return sim.pd_state


def run_for(sim: WegSim, start: float, seconds: float, *words: int, dt: float = 0.05) -> float:
    now = start
    for _ in range(round(seconds / dt)):
        now += dt
        exchange(sim, now, *words)
    return now


# ----------------------------------------------------------------- DP start-up


def test_cfg_prm_and_comm_status() -> None:
    sim = Cfw11Sim(words=4)
    assert sim.expected_cfg() == bytes([0xF3])  # 4 words in and out, consistent
    assert sim.param(740) == 2  # offline after power-up
    assert not sim.check_cfg(bytes([0xF1]))
    assert sim.param(740) == 3  # configuration data error (Table 3.5)
    assert not sim.set_prm(b"\x01")
    assert sim.param(740) == 4  # parameterization data error
    assert sim.set_prm(b"") and sim.check_cfg(bytes([0xF3]))
    assert sim.param(740) == 2
    exchange(sim, 0.1, 0, 0, 0, 0)
    assert sim.param(740) == 6  # online
    assert sim.ext_diag() == b""


def test_telegram_and_profile_change_only_without_cyclic_data() -> None:
    # P0922 / P0741 notes: "assume the new configuration only when ... no cyclic communication"
    sim = Cfw700Sim()
    exchange(sim, 0.1, 0, 0)
    assert sim.write_param(922, 3) is None  # 4 words
    assert sim.write_param(741, 0) is None  # PROFIdrive
    assert sim.expected_cfg() == bytes([0xF1])
    assert len(sim.exchange(bytes(4), 0.2)) == 4
    assert sim.set_prm(b"")
    assert sim.expected_cfg() == bytes([0xF3])
    assert sim.data_profile is DataProfile.PROFIDRIVE


def test_addresses() -> None:
    # CFW-11 P0918 1-125, after a power cycle; CFW700 P0918 1-126 and CFW320 P750 1-126,
    # when there is no cyclic communication
    cfw11 = Cfw11Sim(address=7)
    assert cfw11.address == 7
    assert cfw11.write_param(918, 126) is not None
    assert cfw11.write_param(918, 9) is None
    cfw11.set_prm(b"")
    assert cfw11.address == 7
    cfw11.power_cycle(1.0)
    assert cfw11.address == 9
    cfw700 = Cfw700Sim(address=126)
    assert cfw700.address == 126
    cfw320 = Cfw320Sim(address=3)
    assert (cfw320.address, cfw320.param(750)) == (3, 3)
    assert cfw320.write_param(918, 4) is not None  # no P0918 on the CFW320
    assert cfw320.write_param(750, 4) is None
    cfw320.set_prm(b"")
    assert cfw320.address == 4
    with pytest.raises(ValueError):
        Cfw320Sim(words=7)
    with pytest.raises(ValueError):
        Cfw320Sim(data_profile=DataProfile.PROFIDRIVE)
    with pytest.raises(ValueError):
        Cfw700Sim(data_profile=DataProfile.PROFIDRIVE, frame=20)


def test_identification_parameters() -> None:
    sim = Cfw11Sim(ident_number=0x1234)
    assert sim.ident_number == 0x1234
    assert Cfw320Sim().ident_number == 0x0C32
    assert sim.param(965) == 809
    assert [sim.param(964, i) for i in range(5)][:2] == [367, 4]
    assert Cfw320Sim().param(313) == 1  # CFW320 P313 factory setting 1
    assert Cfw11Sim().param(313) == 0


# ----------------------------------------------------------------- behaviour


def test_ramps_follow_p0100_and_p0101() -> None:
    sim = Cfw11Sim(params=NET)
    # 2.0 s for 1800 rpm; the first telegram (t = 0.05) starts it: 405 rpm at t = 0.5
    now = run_for(sim, 0.0, 0.5, RUN_FWD, 8192)
    assert sim.motor.speed == pytest.approx(405.0)
    assert sim.param(2) == 405
    now = run_for(sim, now, 2.0, RUN_FWD, 8192)
    assert sim.param(681) == 8192
    run_for(sim, now, 0.5, 0x0016, 8192)  # P0101: 0.45 s down at 900 rpm/s
    assert sim.motor.speed == pytest.approx(1395.0)


def test_second_ramp_bit_5() -> None:
    sim = Cfw700Sim(params=NET)
    now = run_for(sim, 0.0, 0.2, RUN_FWD | 0x20, 8192)  # P0102 = 0.5 s: 3600 rpm/s x 0.15 s
    assert sim.motor.speed == pytest.approx(540.0)
    assert exchange(sim, now, RUN_FWD | 0x20, 8192)[0] & 0x20  # P0680 bit 5


def test_quick_stop_bit_6_and_status_bit_4() -> None:
    sim = Cfw11Sim(params=NET)
    now = run_for(sim, 0.0, 3.0, RUN_FWD, 4096)
    status = exchange(sim, now + 0.05, RUN_FWD | 0x40, 4096)[0]
    assert status & 0x0010  # quick stop active
    run_for(sim, now, 1.0, RUN_FWD | 0x40, 4096)
    assert sim.motor.speed == 0.0 and not sim.motor.enabled


def test_cfw320_has_no_quick_stop_and_its_own_status_bits() -> None:
    sim = Cfw320Sim(params=NET)
    now = run_for(sim, 0.0, 3.0, RUN_FWD, 4096)
    status = exchange(sim, now, RUN_FWD | 0x40, 4096)[0]
    assert status & 0x0002  # bit 1: run command
    assert not status & 0x0014  # bit 2 fire mode off; bit 4 reserved
    assert sim.motor.speed == 900.0  # bit 6 "Reserved": no quick stop
    assert not exchange(sim, now + 0.05, 0x0016, 4096)[0] & 0x0002


def test_direction_cases_reach_the_motor() -> None:
    for control, reference, speed in [
        (RUN_FWD, 4096, 900.0),
        (RUN_FWD, -4096, -900.0),
        (0x0013, 4096, -900.0),
        (0x0013, -4096, 900.0),
    ]:
        sim = Cfw11Sim(params=NET)
        run_for(sim, 0.0, 2.0, control, reference & 0xFFFF)
        assert sim.motor.speed == speed
        assert bool(sim.status_word() & 0x0400) is (speed > 0)  # P0680 bit 10


def test_reference_is_limited_to_p0134() -> None:
    sim = Cfw11Sim(params={**NET, 134: 1500})
    run_for(sim, 0.0, 3.0, RUN_FWD, 0x7FFF)
    assert sim.motor.speed == 1500.0


def test_local_remote_and_sources() -> None:
    factory = Cfw11Sim(params={100: 20})  # factory sources: HMI / digital inputs
    run_for(factory, 0.0, 1.0, RUN_FWD, 4096)
    assert factory.motor.speed == 0.0
    assert not factory.status_word() & 0x1000  # local
    net = Cfw11Sim(params=NET)
    now = run_for(net, 0.0, 2.0, RUN_FWD, 4096)
    assert net.status_word() & 0x1000
    now = run_for(net, now, 2.0, RUN_FWD & ~0x10, 4096)  # bit 4 = 0: local, HMI stopped
    assert net.motor.speed == 0.0 and not net.status_word() & 0x1000
    remote = Cfw11Sim(params={**NET, 220: sp.SRC_LOCREM_ALWAYS_REMOTE})
    run_for(remote, 0.0, 2.0, RUN_FWD & ~0x10, 4096)
    assert remote.motor.speed == 900.0


def test_general_enable_and_jog() -> None:
    sim = Cfw700Sim(params=NET)
    # P0680 bit 9: "General Enable is active and the inverter is ready to run the motor",
    # also at standstill with bit 1 set (run/stop 0)
    assert exchange(sim, 0.05, 0x0016, 0)[0] & 0x0200
    assert not exchange(sim, 0.1, 0x0014, 0)[0] & 0x0200  # bit 1 = 0
    sim.undervoltage = True
    assert not exchange(sim, 0.15, 0x0016, 0)[0] & 0x0200
    sim = Cfw700Sim(params=NET)
    now = run_for(sim, 0.0, 3.0, RUN_FWD, 4096)
    status = exchange(sim, now, 0x0015, 4096)[0]  # general enable off: coast
    assert not sim.motor.enabled and not status & 0x0200
    sim = Cfw700Sim(params=NET)
    run_for(sim, 0.0, 1.0, 0x001E, 0)  # JOG
    assert sim.motor.speed == sp.JOG_RPM
    assert sim.status_word() & 0x0800


def test_undervoltage_and_configuration_mode() -> None:
    sim = Cfw11Sim(params=NET)
    sim.undervoltage = True
    run_for(sim, 0.0, 1.0, RUN_FWD, 4096)
    assert sim.motor.speed == 0.0
    assert sim.status_word() & 0x2000
    sim.undervoltage, sim.config_mode = False, True
    assert sim.status_word() & 0x0040


def test_faults_until_reset_edge() -> None:
    sim = Cfw11Sim(params=NET)
    now = run_for(sim, 0.0, 3.0, RUN_FWD, 4096)
    sim.faults.trip(74)  # the shared fault slot: taken at the next tick
    status = exchange(sim, now + 0.05, RUN_FWD, 4096)[0]
    assert status & 0x8000 and not sim.motor.enabled
    assert (sim.param(49), sim.param(944), sim.param(947), sim.param(763)) == (74, 1, 74, 0x20)
    exchange(sim, now + 0.1, RUN_FWD | 0x80, 4096)  # reset while bit held: one edge
    assert sim.fault == 0 and sim.param(944) == 0
    sim.inject_fault(71, now + 0.15)
    exchange(sim, now + 0.2, RUN_FWD | 0x80, 4096)  # no new edge: still faulted
    assert sim.fault == 71
    exchange(sim, now + 0.25, RUN_FWD, 4096)
    exchange(sim, now + 0.3, RUN_FWD | 0x80, 4096)
    assert sim.fault == 0


def test_interface_errors() -> None:
    sim: WegSim = Cfw11Sim()
    sim.interface_error(0.0)
    assert (sim.param(48), sim.param(49)) == (140, 0)  # A140
    sim = Cfw700Sim(params={313: 5})
    sim.interface_error(0.0)
    assert sim.param(49) == 240  # F240
    sim = Cfw320Sim(params={313: 0})
    sim.interface_error(0.0)
    assert sim.param(49) == 32  # F032, always a fault


def test_comm_lost_before_online_is_no_error() -> None:
    # A139 note: "somente será feita se ocorrer a transição de online para offline"
    sim = Cfw11Sim(params={313: 5})
    sim.comm_lost(1.0)
    assert (sim.param(48), sim.param(49)) == (0, 0)


def test_power_cycle() -> None:
    sim = Cfw320Sim(words=3, words_out=(100,), params=NET)
    exchange(sim, 0.1, 0x0016, 0, 35)
    assert sim.param(100) == 35  # written by the cyclic word
    assert sim.write_param(101, 40) is None  # written by a record
    sim.inject_fault(32, 0.2)
    sim.power_cycle(1.0)
    # P746 note: parameters written by the cyclic words are not saved
    assert (sim.param(100), sim.param(101), sim.fault, sim.param(740)) == (20, 40, 0, 2)
    keep = Cfw11Sim(words=3, words_out=(100,), params=NET)
    exchange(keep, 0.1, 0x0016, 0, 35)
    keep.power_cycle(1.0)
    assert keep.param(100) == 35


def test_p0799_delays_the_mapped_output_words() -> None:
    sim = Cfw11Sim(words=3, words_out=(101,), params={**NET, 799: 5})  # 0.5 s
    exchange(sim, 0.1, 0x0016, 0, 35)
    assert sim.param(101) == 20
    exchange(sim, 0.7, 0x0016, 0, 35)
    assert sim.param(101) == 35


def test_mapped_input_words_and_signed_values() -> None:
    sim = Cfw11Sim(words=4, words_in=(685, 0), params=NET)
    assert exchange(sim, 0.1, RUN_FWD, 0xF000, 0, 0)[2:] == (0xF000, 0)


@pytest.mark.parametrize("model", [Cfw11Sim, Cfw700Sim, Cfw320Sim])
def test_keypad_reset_with_the_run_bit_held_runs_again(model: type[WegSim]) -> None:
    """The HMI's reset clears the fault behind the network's back; P0684 bit 0 is a level,
    so a run bit the master still sends starts the motor again (why the gateway clears it)."""
    sim = model(params=NET)
    now = run_for(sim, 0.0, 3.0, RUN_FWD, 4096)
    sim.inject_fault(71, now)
    now = run_for(sim, now, 0.5, RUN_FWD, 4096)
    assert sim.fault == 71 and not sim.motor.enabled
    sim.keypad_reset(now)
    assert sim.fault == 0 and sim.faults.fault_code is None and sim.param(49) == 0
    run_for(sim, now, 0.5, RUN_FWD, 4096)
    assert sim.motor.enabled and sim.motor.reference > 0
    stopped = model(params=NET)
    now = run_for(stopped, 0.0, 1.0, RUN_FWD, 4096)
    stopped.inject_fault(71, now)
    stopped.keypad_reset(now + 0.1)
    run_for(stopped, now + 0.1, 2.0, 0x0016, 4096)  # the master sends stop: it stays stopped
    assert stopped.fault == 0 and stopped.motor.speed == 0.0 and not stopped.running


@pytest.mark.parametrize("model", [Cfw11Sim, Cfw700Sim, Cfw320Sim])
def test_auto_reset_after_p0206_seconds_on_the_sim_clock(model: type[WegSim]) -> None:
    sim = model(params={**NET, 206: 2})
    now = run_for(sim, 0.0, 1.0, 0x0016, 4096)
    sim.inject_fault(71, now)
    assert sim.auto_reset_due() == pytest.approx(now + 2.0)
    exchange(sim, now + 1.95, 0x0016, 4096)
    assert sim.fault == 71
    exchange(sim, now + 2.05, 0x0016, 4096)
    assert sim.fault == 0 and sim.auto_reset_due() is None
    # a tick that jumps past the deadline resets at the deadline, then runs on the level
    sim.inject_fault(72, now + 3.0)
    exchange(sim, now + 3.0, RUN_FWD, 4096)
    assert sim.fault == 72 and not sim.motor.enabled
    exchange(sim, now + 5.5, RUN_FWD, 4096)
    assert sim.fault == 0 and sim.motor.speed > 0  # 0.5 s of ramp since the reset at +5.0
    off = model(params=NET)  # P0206 = 0 (default): no auto-reset
    off.inject_fault(71, 0.0)
    exchange(off, 300.0, 0x0016, 4096)
    assert off.fault == 71 and off.auto_reset_due() is None


def test_profidrive_auto_reset_goes_to_switching_on_inhibited() -> None:
    """PROFIdrive: after any reset the drive is in S1 and needs ON = 0 before it runs
    (fact sheet 1.11), so a held ON does not restart it by itself."""
    sim = Cfw11Sim(data_profile=DataProfile.PROFIDRIVE, params={**NET, 206: 1})
    exchange(sim, 0.05, 0x047E, 0x2000)
    now = run_for(sim, 0.05, 1.0, 0x047F, 0x2000)
    assert state(sim) is PdState.S4 and sim.motor.speed > 0
    sim.inject_fault(71, now)
    now = run_for(sim, now, 1.5, 0x047F, 0x2000)
    assert sim.fault == 0 and state(sim) is PdState.S1 and not sim.motor.enabled


def test_profidrive_state_machine_in_the_sim() -> None:
    sim = Cfw700Sim(data_profile=DataProfile.PROFIDRIVE, params=NET)
    assert exchange(sim, 0.05, 0x0000, 0)[0] & 0x0040  # S1: switching on inhibited
    assert sim.pd_state is PdState.S1
    exchange(sim, 0.1, 0x045F, 0x2000)  # ON while inhibited: stays in S1
    assert state(sim) is PdState.S1
    zsw = exchange(sim, 0.15, 0x045E, 0x2000)[0]
    assert state(sim) is PdState.S2 and zsw & 0x0001
    exchange(sim, 0.2, 0x0457, 0x2000)  # ON without enable operation: switched on
    assert state(sim) is PdState.S3
    now = run_for(sim, 0.2, 1.0, 0x045F, 0x2000)
    assert state(sim) is PdState.S4 and sim.motor.speed > 0
    now = run_for(sim, now, 2.0, 0x041F, 0x2000)  # bit 6 = 0: reference zeroed
    assert sim.motor.speed == 0.0
    assert sim.param(685) == 0
