"""The full-plant benchmark's machinery, run tiny (the figures are `make bench`'s; no timing
is asserted here): the processes start, every drive comes online over the bench CAN bus and
the paced pty, the clients are answered, and every process ends."""

from __future__ import annotations

import math
import re
import socket
import threading
from pathlib import Path

import can
from hypothesis import given
from hypothesis import strategies as st

from bench import bench_plant
from bench.plant import canbus
from gateway.config import parse


@given(st.integers(0, 0x7FF), st.binary(max_size=8))
def test_frame_bits_lie_between_no_stuffing_and_the_worst_case(ident: int, data: bytes) -> None:
    bits = canbus.frame_bits(ident, data)
    stuffed_region = 34 + 8 * len(data)  # SOF to the end of the CRC
    assert 47 + 8 * len(data) <= bits <= 47 + 8 * len(data) + (stuffed_region - 1) // 4


def test_frame_bits_count_stuff_bits() -> None:
    # identifier 0 and data 0: SOF, 11 + 3 dominant bits and DLC 0 make a run of 19 zeros
    # (4 stuff bits so far); a recessive-rich frame needs fewer
    assert canbus.frame_bits(0x000, b"") > canbus.frame_bits(0x555, b"")
    assert canbus.frame_bits(0x555, b"\x55" * 8) == 47 + 64 + _crc_stuff(0x555, b"\x55" * 8)


def _crc_stuff(ident: int, data: bytes) -> int:
    """Stuff bits of a frame whose header and data alternate (none there): the CRC's only."""
    return canbus.frame_bits(ident, data) - 47 - 8 * len(data)


def test_felser_cycle_of_the_plant_line() -> None:
    request, reply = bench_plant.exchange_bits()
    assert (request, reply) == (14 * 11, 14 * 11)  # 8 data bytes: SD3 both ways (1.2)
    bus = bench_plant.bus_params()
    per_slave = (request + reply + bus.min_tsdr + 33) / bus.baudrate
    assert bench_plant.felser_cycle(125) > 125 * per_slave
    assert bench_plant.felser_cycle(125) < 1.02 * 125 * per_slave  # Global_Control: ~1 %


def test_canopen_minimum_counts_the_frames_the_master_maps() -> None:
    drives = [
        {"id": "d1", "device": "CiA 402", "address": 1, "eds": "eds/cia402-drive.eds"},
    ]
    bus = {"adapter": "canopen", "interface": "virtual", "channel": "x", "drives": drives}
    config = parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": bus}}, "t"
    )
    opts = config.buses[0].drives[0].options
    rpdo = (opts.controlword.bits + opts.target.bits) // 8
    tpdo = (opts.statusword.bits + opts.actual.bits + sum(v.bits for v in opts.extras)) // 8
    assert (rpdo, tpdo) == (bench_plant.CANOPEN_RPDO1_BYTES, bench_plant.CANOPEN_TPDO1_BYTES)
    # SYNC (0 bytes) + 32 x (RPDO1 + TPDO1): about 13.7 ms at 500 kbit/s
    plain = 47 + 32 * (47 + 8 * rpdo + 47 + 8 * tpdo)
    assert plain / 500_000 < bench_plant.canopen_cycle(32) < 1.25 * plain / 500_000
    assert bench_plant.canopen_sync_period(32) >= bench_plant.canopen_cycle(32)
    # the period the bench configures is one the configuration takes (its worst-case floor)
    for nodes in (1, 2, 32):
        table = {**bus, "bitrate": 500_000, "sync_period": bench_plant.canopen_sync_period(nodes)}
        table["drives"] = [{**drives[0], "id": f"d{n}", "address": n} for n in range(1, nodes + 1)]
        parse(
            {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"co": table}}, "t"
        )


def test_the_bench_bus_carries_frames_between_processes_paced(tmp_path: Path) -> None:
    path = str(tmp_path / "can.sock")
    broker = canbus.Broker(path, 500_000)
    runner = threading.Thread(target=broker.run)
    runner.start()
    canbus.register()
    try:
        with (
            can.Bus(interface=canbus.INTERFACE, channel=path) as a,
            can.Bus(interface=canbus.INTERFACE, channel=path) as b,
        ):
            sent = [can.Message(arbitration_id=0x400 + i, data=bytes([i] * 4)) for i in range(3)]
            sent.append(can.Message(arbitration_id=0x3C1, data=b"\x01\x02"))
            for msg in sent:
                a.send(msg)
            got = [b.recv(5.0) for _ in sent]
            assert all(m is not None for m in got)
            # queued in one sender: its own order (a transmit FIFO), whatever the identifiers
            assert [m.arbitration_id for m in got if m] == [m.arbitration_id for m in sent]
            assert [bytes(m.data) for m in got if m] == [bytes(m.data) for m in sent]
            assert a.recv(0) is None  # nobody hears their own frames
    finally:
        broker.stop = True
        with socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET) as poke:
            poke.connect(path)  # wakes the broker's select
        runner.join()
        broker.listener.close()
        for client in broker.clients:
            client.close()
    assert len(broker.ends) == len(sent)
    # paced: a frame ends no sooner than its own bit time after the one before (back to back
    # when the sender's frames reached the broker while the bus was busy; later when a loaded
    # machine delivered one after the bus fell idle)
    gaps = [b - a for a, b in zip(broker.ends[1:-1], broker.ends[2:], strict=True)]
    times = [bits / 500_000 for bits in broker.bits[2:]]
    assert all(gap >= t * (1 - 1e-6) for gap, t in zip(gaps, times, strict=True)), (gaps, times)


def test_a_tiny_plant_runs_and_stops() -> None:
    plant = bench_plant.Plant(
        profibus=2,
        devicenet=2,
        canopen=2,
        modbus_clients=2,
        modbus_rate=5.0,
        seconds=2.5,
        settle=0.5,
    )
    figures = {f.name: f for f in bench_plant.measure(plant)}
    assert all(proc.poll() is not None for proc in plant.procs.values())
    assert figures["plant_gateway_cpu"].value > 0
    assert figures["plant_gateway_rss"].value > 0
    come_up = figures["plant_come_up"]
    assert 0 < come_up.value <= bench_plant.STARTUP_BOUND and "Profibus cycles" in come_up.note
    for line in ("profibus_2_slaves_1500k", "devicenet_2_nodes_500k", "canopen_2_nodes_500k"):
        cycle = figures[f"plant_{line}_cycle"]
        assert not math.isnan(cycle.value)
        assert cycle.reference is not None and cycle.reference > 0
    # the launcher hands over the Profibus line's error counters for the cycle's note
    assert re.search(
        r"errors over the whole run .*retries \d+, timeouts \d+",
        figures["plant_profibus_2_slaves_1500k_cycle"].note,
    )
    modbus = figures["plant_modbus_poll_rate"]
    assert modbus.value > 0 and "0 exceptions" in modbus.note
    assert "6 of 6 drives seen" in figures["plant_zenoh_states"].note
    # the CPU by part: each line's thread, the loop (split by what it runs), Zenoh's threads
    assert figures["plant_gateway_cpu_zenoh"].value >= 0  # its native threads: 10 ms ticks
    for part in ("line_profibus", "line_devicenet", "line_canopen", "loop"):
        assert figures[f"plant_gateway_cpu_{part}"].value > 0, part
    assert figures["plant_gateway_cpu_loop_modbus"].value > 0  # its requests, timed
    turnaround = figures["plant_profibus_turnaround_p99"]
    assert turnaround.reference is not None and turnaround.value >= turnaround.reference > 0
    # the pty's own round trip in the same window, at the simulator's priority
    pty = figures["plant_pty_round_trip_p99"]
    assert pty.reference is not None and pty.value >= pty.reference > 0
    assert "plant_profibus_turnaround_p99_less_pty" in figures


def test_the_line_errors_of_every_profibus_line_are_summed() -> None:
    lines = [{"retries": 2, "timeouts": 1}, {"retries": 3, "timeouts": 0}]
    assert bench_plant._line_errors(lines).endswith("retries 5, timeouts 1")
    assert bench_plant._line_errors([]) == ""
