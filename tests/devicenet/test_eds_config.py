"""The ``eds`` drive key, the scanner's Duplicate MAC ID vendor ID setting (issue 20)."""

from __future__ import annotations

from pathlib import Path

import pytest

from adapters.devicenet.adapter import DeviceNetAdapter
from adapters.devicenet.cfw08.options import DriveOptions
from adapters.devicenet.codec.dupmac import DupMacCheck
from adapters.devicenet.options import SCANNER_VENDOR_ID
from adapters.devicenet.scanner import Scanner, Send
from adapters.devicenet.sim.simulated import sim_configs
from gateway.config import load
from gateway.errors import ConfigErrors

ROOT = Path(__file__).resolve().parents[2]
CFW08_EDS = ROOT / "config" / "eds" / "cfw08-test.eds"
BUS = "[buses.dn]\nadapter = 'devicenet'\n"
DRIVE = "[[buses.dn.drives]]\nid = 'd'\ndevice = 'CFW-08'\naddress = 5\nmax_rpm = 1800\n"
D = "buses.dn.drives[d]"


def write(tmp_path: Path, text: str, eds: str | None = None) -> Path:
    if eds is not None:
        (tmp_path / "cfw08.eds").write_text(eds)
    path = tmp_path / "site.toml"
    path.write_text(text)
    return path


def errors(tmp_path: Path, text: str, eds: str | None = None) -> list[str]:
    with pytest.raises(ConfigErrors) as err:
        load(write(tmp_path, text, eds))
    return [str(e).replace(str(tmp_path) + "/", "") for e in err.value.errors]


def test_identity_sizes_and_parameters_come_from_the_eds(tmp_path: Path) -> None:
    # a path relative to the config file
    config = load(write(tmp_path, BUS + DRIVE + "eds = 'cfw08.eds'\n", CFW08_EDS.read_text()))
    opts: DriveOptions = config.buses[0].drives[0].options
    assert (opts.vendor_id, opts.product_code, opts.product_name) == (0x355, 8, "CFW-08")
    assert (opts.product_type, opts.revision, opts.io_sizes) == (2, (4, 6), (4, 4))
    assert sorted(opts.params) == [3, 100, 101, 313, 402]
    assert opts.params[100].name == "Acceleration time"
    node = DeviceNetAdapter(config.buses[0]).node_configs()[0]
    assert (node.identity.product_type, node.identity.revision) == (2, (4, 6))
    sim = sim_configs(config.buses[0])[0]
    assert sim.identity is not None and sim.identity.revision == (4, 6)
    assert sim.io_sizes == (4, 4)


def test_eds_sizes_must_fit_the_assemblies_in_use(tmp_path: Path) -> None:
    eds = CFW08_EDS.read_text().replace("4,                        $ bytes", "8, $", 1)
    assert errors(tmp_path, BUS + DRIVE + "eds = 'cfw08.eds'\n", eds) == [
        f"site.toml: {D}.eds: cfw08.eds: the POLL connection is 8 bytes in, 4 "
        "bytes out; the CFW-08 assemblies in use are 4 and 4 (seed table 11)"
    ]


def test_eds_without_the_configured_connection(tmp_path: Path) -> None:
    eds = CFW08_EDS.read_text().replace("    COSInfo = 0x0004, 1, 1;\n", "")
    text = BUS + DRIVE + "eds = 'cfw08.eds'\nconnection = 'cos'\n"
    assert errors(tmp_path, text, eds) == [
        f"site.toml: {D}.eds: cfw08.eds has no COS connection in [IO_Info]"
    ]


def test_a_bad_eds_names_the_config_key_and_the_eds_line(tmp_path: Path) -> None:
    eds = CFW08_EDS.read_text().replace("ProdType = 2;", "ProdType = two;")
    assert errors(tmp_path, BUS + DRIVE + "eds = 'cfw08.eds'\n", eds) == [
        f"site.toml: {D}.eds: cfw08.eds: line 17: [Device] ProdType: "
        "field 1 (ProdType) 'two' is not a number"
    ]


def test_config_keys_that_contradict_the_eds(tmp_path: Path) -> None:
    text = BUS + DRIVE + "eds = 'cfw08.eds'\nproduct_code = 9\n"
    assert errors(tmp_path, text, CFW08_EDS.read_text()) == [
        f"site.toml: {D}.product_code: 9 differs from the EDS (cfw08.eds: 8)"
    ]


def _dupmac_vendor(adapter: DeviceNetAdapter) -> int:
    engine = Scanner(adapter.scanner_config(), adapter.node_configs())
    frames = [a.frame for a in engine.step(0.0) if isinstance(a, Send)]
    return DupMacCheck.from_frame(frames[0]).vendor_id


def test_duplicate_mac_vendor_id_default_is_not_reserved(tmp_path: Path) -> None:
    config = load(write(tmp_path, BUS + DRIVE))
    assert _dupmac_vendor(DeviceNetAdapter(config.buses[0])) == SCANNER_VENDOR_ID == 0xFFFF


def test_duplicate_mac_vendor_id_setting(tmp_path: Path) -> None:
    config = load(write(tmp_path, BUS + "vendor_id = 0x1234\n" + DRIVE))
    assert _dupmac_vendor(DeviceNetAdapter(config.buses[0])) == 0x1234
    assert errors(tmp_path, BUS + "vendor_id = 70000\n" + DRIVE) == [
        "site.toml: buses.dn.vendor_id: 70000 is above the maximum 65535"
    ]
