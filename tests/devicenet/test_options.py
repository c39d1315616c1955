"""The DeviceNet bus table and drive keys: defaults, and every error message exactly."""

from __future__ import annotations

from pathlib import Path

import pytest

from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.cfw08 import AssemblyPair
from adapters.devicenet.cfw08.options import DriveOptions, SimOptions
from adapters.devicenet.options import BusOptions
from adapters.devicenet.scanner import IoKind
from gateway.config import load
from gateway.errors import AdapterError, ConfigErrors

BUS = "[buses.dn]\nadapter = 'devicenet'\n"
DRIVE = "[[buses.dn.drives]]\nid = 'd'\ndevice = 'CFW-08'\naddress = 5\nmax_rpm = 1800\n"


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "site.toml"
    path.write_text(text)
    return path


def test_defaults(tmp_path: Path) -> None:
    config = load(write(tmp_path, BUS + DRIVE))
    bus = config.buses[0]
    assert bus.options == BusOptions()
    assert (bus.options.interface, bus.options.channel, bus.options.bitrate) == (
        "socketcan",
        "can0",
        125_000,
    )
    opts: DriveOptions = bus.drives[0].options
    assert opts.assembly is AssemblyPair.EXTENDED and opts.connection is IoKind.POLLED
    assert (opts.vendor_id, opts.product_name, opts.max_rpm) == (0x355, "CFW-08", 1800.0)
    assert opts.sim == SimOptions()


def test_every_key(tmp_path: Path) -> None:
    text = (
        BUS + "interface = 'virtual'\nchannel = 'line-a'\nbitrate = 500000\nmac = 1\n"
        "poll_interval = 0.02\nexpected_packet_rate = 0.1\nresponse_timeout = 0.05\n"
        "explicit_timeout = 0.5\nexplicit_epr = 4\ndupmac_timeout = 0.1\nretry_max = 5\n"
        "status_interval = 1\n"
        "simulate = true\n"
        "[[buses.dn.drives]]\nid = 'd'\ndevice = 'CFW-08'\naddress = 5\nassembly = 100\n"
        "connection = 'cos'\nack = false\ncheck_identity = false\nvendor_id = 1\n"
        "product_code = 7\nproduct_name = 'X'\nmax_rpm_param = 402\nweg_speed_scale = 16384\n"
        "at_reference_rpm = 10\nsim_p313 = 1\nsim_p710 = 2\nsim_ramp_time = 0.5\n"
        "sim_max_rpm = 3600\n"
        "[buses.dn.drives.startup_params]\nP313 = 1\n100 = 20\n"
    )
    bus = load(write(tmp_path, text)).buses[0]
    assert bus.options == BusOptions(
        "virtual", "line-a", 500_000, 1, 0.02, 0.1, 0.05, 0.5, 0.1, 5.0, 1.0, True, explicit_epr=4.0
    )
    opts: DriveOptions = bus.drives[0].options
    assert opts.assembly is AssemblyPair.WEG and opts.connection is IoKind.COS and not opts.ack
    assert opts.startup_params == ((313, 1), (100, 20))
    assert (opts.max_rpm, opts.max_rpm_param, opts.weg_speed_scale) == (None, 402, 16384)
    assert opts.sim == SimOptions(p313=1, p710=2, ramp_time=0.5, max_rpm=3600.0)


D = "buses.dn.drives[d]"
BROKEN = [
    (BUS + "interface = 'udp_multicast'\n",
     "buses.dn.interface: udp_multicast is not supported: it sends multicast out of the network "
     "interface and loses frames; use virtual (in-process) or socketcan (vcan0)"),
    (BUS + "interface = ''\n", "buses.dn.interface: must name a python-can interface"),
    (BUS + "bitrate = 100000\n", "buses.dn.bitrate: 100000 is not a DeviceNet rate (125000, 250000, 500000)"),
    (BUS + "mac = 64\n", "buses.dn.mac: 64 is above the maximum 63"),
    (BUS + "poll_interval = 0.1\nexpected_packet_rate = 0.05\n",
     "buses.dn.expected_packet_rate: 0.05 s is shorter than poll_interval (0.1 s)"),
    (BUS + "explicit_timeout = 3\nexplicit_epr = 2\n",
     "buses.dn.explicit_epr: 2 s is shorter than explicit_timeout (3 s)"),
    (BUS + "explicit_epr = 70\n", "buses.dn.explicit_epr: 70 is above the maximum 65.535"),
    (BUS + "simulate = true\n",
     "buses.dn.simulate: needs interface = 'virtual' (simulated drives run in-process), not 'socketcan'"),
    (BUS + "simulate = 'yes'\n", "buses.dn.simulate: must be true or false, not a string"),
    (BUS + "baud = 125000\n", "buses.dn.baud: unknown key"),
    (BUS + DRIVE.replace("5", "64"), f"{D}.address: 64 is above the maximum 63"),
    (BUS + DRIVE.replace("CFW-08", "CFW-11"), f"{D}.device: 'CFW-11' is not one of 'CFW-08'"),
    (BUS + DRIVE + "assembly = 70\n", f"{D}.assembly: 70 is not an assembly (20, 21, 100)"),
    (BUS + DRIVE.replace("max_rpm = 1800\n", ""),
     f"{D}.max_rpm: is required (or max_rpm_param to read it at connect)"),
    (BUS + DRIVE + "max_rpm_param = 402\n", f"{D}.max_rpm_param: give max_rpm or max_rpm_param, not both"),
    (BUS + DRIVE.replace("1800", "10000"), f"{D}.max_rpm: 10000 is above the maximum 9999"),
    (BUS + DRIVE + "connection = 'strobe'\n", f"{D}.connection: 'strobe' is not one of 'polled', 'cos', 'cyclic'"),
    (BUS + DRIVE + "ack = false\n", f"{D}.ack: false needs connection = 'cos' or 'cyclic'"),
    (BUS + DRIVE + "[buses.dn.drives.startup_params]\nP900 = 1\n",
     f"{D}.startup_params.P900: is not a CFW-08 parameter number (P000-P799)"),
    (BUS + DRIVE + "[buses.dn.drives.startup_params]\nspeed = 1\n",
     f"{D}.startup_params.speed: is not a CFW-08 parameter number (P000-P799)"),
    (BUS + DRIVE + "[buses.dn.drives.startup_params]\nP313 = 'one'\n",
     f"{D}.startup_params.P313: must be an integer, not a string"),
    (BUS + DRIVE + "[buses.dn.drives.startup_params]\nP313 = 70000\n",
     f"{D}.startup_params.P313: 70000 is above the maximum 65535"),
    (BUS + DRIVE + "startup_params = [313, 1]\n", f"{D}.startup_params: must be a table, not an array"),
    (BUS + DRIVE + "sim_p313 = 4\n", f"{D}.sim_p313: 4 is above the maximum 3"),
    (BUS + DRIVE + "weg_speed_scale = 0\n", f"{D}.weg_speed_scale: 0 is below the minimum 1"),
    (BUS + DRIVE + "vendor = 853\n", f"{D}.vendor: unknown key (did you mean 'vendor_id'?)"),
]  # fmt: skip


@pytest.mark.parametrize(("text", "message"), BROKEN)
def test_broken_config_gives_its_exact_message(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigErrors) as err:
        load(write(tmp_path, text))
    messages = [str(e).replace(str(tmp_path) + "/", "") for e in err.value.errors]
    assert messages == [f"site.toml: {message}"]


def test_drive_on_the_scanner_mac_is_refused(tmp_path: Path) -> None:
    config = load(write(tmp_path, BUS + "mac = 5\n" + DRIVE))
    with pytest.raises(AdapterError, match="drive d has the scanner's MAC ID 5"):
        DeviceNetAdapter(config.buses[0])
