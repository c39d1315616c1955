"""The OPC UA benchmark on a tiny plant: the three runs happen (without, with, without
again), the sessions subscribe to every drive, and every figure is there (the figures
themselves are make bench's)."""

from __future__ import annotations

import math

from bench import bench_opcua


def test_a_tiny_plant_with_and_without_opcua() -> None:
    without, with_opcua, again = bench_opcua.plants(2.0, 2, profibus=2, devicenet=0, canopen=0)
    for plant in (without, with_opcua, again):
        plant.modbus_clients = 1
        plant.settle = 3.0
    figures = {f.name: f for f in bench_opcua.compare(without, with_opcua, again)}
    rate = figures["opcua_profibus_cycle_rate"]
    assert rate.value > 0 and rate.reference is not None and rate.reference > 0
    assert "a run before" in rate.note and again.raw["cycles"]["profibus"]
    assert "opcua_devicenet_cycle_rate" not in figures  # no such line in this plant
    assert figures["opcua_sessions_up"].value == 2
    assert "16 monitored items" in figures["opcua_notifications"].note  # 2 x 2 drives x 4
    assert not math.isnan(figures["opcua_server_cpu_share"].value)
    assert "opcua-clients" not in without.raw["clients"]
    assert "opcua-clients" not in again.raw["clients"]
