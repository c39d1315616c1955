"""``drive-gateway params`` backup, diff and restore, and the ``<prefix>/drives/<id>/params``
queryable, against a gateway process with one simulated drive of each family: WEG CFW-11
and CFW320 over DP-V1, the MCD 600 in parameter mode (one Profibus line on a pty), the
CFW-08 over DeviceNet explicit messages and a CiA 402 drive over CANopen SDO (python-can
``virtual``)."""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.support.net import zenoh_endpoint
from tests.support.timing import scaled
from tests.zenoh.client import Client
from tests.zenoh.conftest import READY_LINE, GatewayProcess

ROOT = Path(__file__).resolve().parents[2]
PREFIX = "paramtest"
WEG_STARTUP = "{ P0220 = 10, P0222 = 11, P0226 = 9, P0227 = 4, P0228 = 5, P0105 = 5, P0313 = 1 }"


def config(channel: str, co_channel: str) -> str:
    return f"""
[gateway]
name = "params-test"
shutdown_timeout = 3.0
tick = 0.01
[zenoh]
prefix = "{PREFIX}"
heartbeat = 0.2
multicast_scouting = false
[modbus]
enabled = false

[buses.pb]
adapter = "profibus"
simulate = true
baudrate = 500000
# the demo's margins (config/demo.toml): the slaves answer from the gateway's own loop
watchdog = 2.0
latency = 0.05
retries = 2
absent_retry = 0.1
fault_retry = 0.2
live_list_period = 0.0

[[buses.pb.drives]]
id = "cfw11"
device = "CFW-11"
address = 3
writable_params = [100, 101]
data_profile = "profidrive"
frame = 20
startup_params = {WEG_STARTUP}

[[buses.pb.drives]]
id = "cfw320"
device = "CFW320"
address = 5
writable_params = [100, 101]
data_profile = "manufacturer"
words = 2
startup_params = {WEG_STARTUP}

[[buses.pb.drives]]
id = "mcd600"
device = "MCD 600"
address = 6
mode = "parameter"
writable_params = [4, 9]

[buses.dn]
adapter = "devicenet"
interface = "virtual"
channel = "{channel}"
simulate = true
bitrate = 125000
mac = 0
poll_interval = 0.05
expected_packet_rate = 0.2

[[buses.dn.drives]]
id = "cfw08"
device = "CFW-08"
address = 5
assembly = 21
connection = "polled"
max_rpm = 1800
writable_params = [100, 101, 313]

[buses.co]
adapter = "canopen"
interface = "virtual"
channel = "{co_channel}"
simulate = true
bitrate = 500000
sync_period = 0.05
heartbeat = 100

[[buses.co.drives]]
id = "co"
device = "CiA 402"
address = 10
eds = "eds/cia402-drive.eds"
max_rpm = 1800
heartbeat = 100
writable_params = ["0x6083", "0x2000:4"]
"""


DRIVES = ("cfw11", "cfw320", "mcd600", "cfw08", "co")


@pytest.fixture(scope="module")
def gw(tmp_path_factory: pytest.TempPathFactory) -> Iterator[GatewayProcess]:
    tmp = tmp_path_factory.mktemp("params")
    cfg = tmp / "gateway.toml"
    cfg.write_text(config(f"params-{uuid.uuid4().hex[:8]}", f"params-co-{uuid.uuid4().hex[:8]}"))
    gateway = GatewayProcess(cfg, zenoh_endpoint())
    try:
        gateway.wait_for_line(READY_LINE, timeout=scaled(30))
        client = Client(gateway.endpoint)
        try:
            for drive in DRIVES:
                with client.liveliness(f"{PREFIX}/drives/{drive}") as live:
                    live.until(lambda s: s.put, timeout=scaled(30))
        finally:
            client.close()
    except BaseException:
        gateway.kill()
        raise
    yield gateway
    assert gateway.stop() == 0, "".join(gateway.log)


def tool(gw: GatewayProcess, *args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    words = 2 if args[0] == "params" else 1  # the options belong to the (sub)command
    common = ["--connect", gw.endpoint, "--prefix", PREFIX]
    argv = [sys.executable, "-m", "gateway", *args[:words], *common, *args[words:]]
    return subprocess.run(
        argv, cwd=cwd, capture_output=True, text=True, timeout=scaled(120), check=False
    )


def backup(gw: GatewayProcess, tmp: Path, drive: str, *extra: str) -> dict[str, Any]:
    out = tmp / f"{drive}.json"
    done = tool(gw, "params", "backup", drive, "-o", str(out), *extra)
    assert done.returncode == 0, done.stderr
    assert f"-> {out}" in done.stdout
    doc: dict[str, Any] = json.loads(out.read_text())
    return doc


def by_number(doc: dict[str, Any]) -> dict[int, dict[str, Any]]:
    return {p["number"]: p for p in doc["params"]}


def test_backup_of_a_weg_drive_reads_its_whole_table(gw: GatewayProcess, tmp_path: Path) -> None:
    from adapters.profibus.weg.paramtable import PARAM_TABLES
    from gateway.model import Device

    doc = backup(gw, tmp_path, "cfw320")
    assert (doc["schema"], doc["version"]) == ("drive-gateway/params-backup", 1)
    assert doc["drive"]["id"] == "cfw320" and doc["drive"]["device"] == "CFW320"
    assert doc["drive"]["bus"] == "pb" and doc["drive"]["address"] == 5
    assert doc["gateway"].startswith("params-test ")
    assert doc["taken"].endswith("+00:00")
    params = by_number(doc)
    assert sorted(params) == sorted(PARAM_TABLES[Device.CFW320])  # every table parameter
    p100 = params[100]
    assert (p100["code"], p100["name"], p100["unit"]) == ("P100", "Acceleration time", "s")
    assert p100["scaled"] == p100["raw"] / 10


def test_backup_of_a_list_names_firmware_and_keeps_refusals(
    gw: GatewayProcess, tmp_path: Path
) -> None:
    doc = backup(gw, tmp_path, "cfw11", "--params", "P0100-101,23,999")
    assert doc["drive"]["firmware"] == "5.00" and doc["drive"]["firmware_source"] == "P0023"
    params = by_number(doc)
    assert list(params) == [100, 101, 23, 999]
    assert params[23]["name"] == "Software version"
    assert "error" in params[999] and "raw" not in params[999]  # the device's refusal, kept


def test_backup_of_the_mcd600_in_parameter_mode(gw: GatewayProcess, tmp_path: Path) -> None:
    """No table (docs/devices.md): a list is needed; an unknown number is the starter's
    own refusal (invalid parameter number) and the backup goes on."""
    refused = tool(gw, "params", "backup", "mcd600", "-o", str(tmp_path / "x.json"))
    assert refused.returncode == 1 and "no parameter table" in refused.stderr
    doc = backup(gw, tmp_path, "mcd600", "--params", "1-4,200")
    params = by_number(doc)
    assert [params[n].get("raw") is not None for n in (1, 2, 3, 4)] == [True] * 4
    assert "invalid" in params[200]["error"].lower() and params[200]["error_code"] == 1
    assert doc["drive"]["firmware"] == "1.4"  # data request 15 in the state values


def test_backup_of_the_cfw08_without_eds_reads_the_seed_table(
    gw: GatewayProcess, tmp_path: Path
) -> None:
    from adapters.devicenet.cfw08.objects import SEED_PARAMETERS

    doc = backup(gw, tmp_path, "cfw08")
    params = by_number(doc)
    assert sorted(params) == sorted(SEED_PARAMETERS)
    assert params[701]["raw"] == 5  # its MAC ID
    assert params[313]["code"] == "P313" and "error" not in params[313]


def test_diff_and_restore_a_weg_drive(gw: GatewayProcess, tmp_path: Path) -> None:
    doc = backup(gw, tmp_path, "cfw11", "--params", "100,101,134")
    p100 = by_number(doc)[100]["raw"]
    p134 = by_number(doc)[134]["raw"]
    file = tmp_path / "cfw11.json"
    wrote = tool(gw, "param", "cfw11", "write", "100", str(p100 + 7))
    assert wrote.returncode == 0, wrote.stderr
    for entry in doc["params"]:  # a value the drive's writable_params does not allow
        if entry["number"] == 134:
            entry["raw"] = p134 + 1
    file.write_text(json.dumps(doc))

    diff = tool(gw, "params", "diff", str(file), "cfw11")
    assert diff.returncode == 1, diff.stderr
    rows = {line.split()[0]: line for line in diff.stdout.splitlines()[1:-1]}
    assert set(rows) == {"P0100", "P0134"} and "differs" in rows["P0100"]
    file_side, drive_side = f"{p100 / 10} s", f"{(p100 + 7) / 10} s"  # both in the unit
    assert rows["P0100"].split()[3:8] == [*file_side.split(), *drive_side.split(), "differs"]
    assert diff.stdout.splitlines()[-1] == "2 of 3 parameter(s) differ"

    dry = tool(gw, "params", "restore", str(file), "cfw11", "--dry-run", "--json")
    assert dry.returncode == 0, dry.stderr
    results = {r["parameter"]: r for r in json.loads(dry.stdout)["results"]}
    assert results["P0100"]["result"] == "would write"
    assert results["P0134"]["result"] == "skipped"
    assert "writable_params" in results["P0134"]["reason"]
    assert results["P0101"]["result"] == "same"
    still = tool(gw, "param", "cfw11", "read", "100")
    assert still.stdout.startswith(f"P0100 Acceleration time = {(p100 + 7) / 10}")

    done = tool(gw, "params", "restore", str(file), "cfw11")
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "cfw11: 1 same, 1 skipped, 1 written"
    back = tool(gw, "param", "cfw11", "read", "100")
    assert back.stdout.startswith(f"P0100 Acceleration time = {p100 / 10}")

    two_files = tmp_path / "copy.json"
    two_files.write_text(json.dumps(doc))
    same = tool(gw, "params", "diff", str(file), str(two_files), "--json")
    assert same.returncode == 0 and json.loads(same.stdout)["differences"] == 0


def test_restore_refuses_a_running_drive_and_another_model(
    gw: GatewayProcess, tmp_path: Path
) -> None:
    backup(gw, tmp_path, "cfw11", "--params", "100")
    file = tmp_path / "cfw11.json"
    other = tool(gw, "params", "restore", str(file), "cfw320")
    assert other.returncode == 1 and "is a CFW320" in other.stderr
    run = tool(gw, "cmd", "cfw11", "run", "--speed-rpm", "300")
    assert run.returncode == 0, run.stderr + run.stdout
    try:
        refused = tool(gw, "params", "restore", str(file), "cfw11")
        assert refused.returncode == 1
        assert "restore refused: drive cfw11 is running" in refused.stderr
    finally:
        stop = tool(gw, "cmd", "cfw11", "stop")
        assert stop.returncode == 0, stop.stderr


def test_restore_over_devicenet_explicit_messages(gw: GatewayProcess, tmp_path: Path) -> None:
    doc = backup(gw, tmp_path, "cfw08", "--params", "313")
    old = by_number(doc)[313]["raw"]
    new = 1 if old != 1 else 2
    assert tool(gw, "param", "cfw08", "write", "313", str(new)).returncode == 0
    done = tool(gw, "params", "restore", str(tmp_path / "cfw08.json"), "cfw08", "--json")
    assert done.returncode == 0, done.stderr
    (result,) = json.loads(done.stdout)["results"]
    assert result["result"] == "written" and result["drive"] == str(new)
    assert tool(gw, "param", "cfw08", "read", "313").stdout.endswith(f"= {old}\n")


def test_restore_a_canopen_subindex_entry_of_writable_params(
    gw: GatewayProcess, tmp_path: Path
) -> None:
    """``writable_params = ["0x6083", "0x2000:4"]``: the describe answer lists the entry,
    the backup reads 0x2000:4 and a restore writes that subindex back over SDO."""
    client = Client(gw.endpoint)
    try:
        (described,) = client.query(f"{PREFIX}/drives/co/params?describe", timeout=scaled(30))
        assert described.json()["writable_entries"] == [[0x2000, 4]]
    finally:
        client.close()
    doc = backup(gw, tmp_path, "co")
    entries = {(p["number"], p.get("subindex", 0)): p for p in doc["params"]}
    old = entries[(0x2000, 4)]["raw"]
    new = old + 100
    wrote = tool(gw, "param", "co", "write", "0x2000:4", str(new))
    assert wrote.returncode == 0, wrote.stderr
    done = tool(gw, "params", "restore", str(tmp_path / "co.json"), "co", "--json")
    assert done.returncode == 0, done.stderr
    results = {r["parameter"]: r for r in json.loads(done.stdout)["results"]}
    (mine,) = [r for r in results.values() if r["result"] == "written"]
    assert mine["drive"] == str(new)
    back = tool(gw, "param", "co", "read", "0x2000:4")
    assert back.returncode == 0 and back.stdout.rstrip().endswith(f"= {old}"), back.stdout


def test_the_params_queryable_answers_the_whole_document(gw: GatewayProcess) -> None:
    """SCADA's way: one query on <prefix>/drives/<id>/params, no number."""
    client = Client(gw.endpoint)

    def one(selector: str) -> Any:
        (reply,) = client.query(selector, timeout=scaled(30))
        return reply

    try:
        reply = one(f"{PREFIX}/drives/cfw08/params")
        assert reply.ok, reply.json()
        doc = reply.json()
        assert doc["schema"] == "drive-gateway/params-backup" and doc["drive"]["id"] == "cfw08"
        assert len(doc["params"]) == 14
        listed = one(f"{PREFIX}/drives/mcd600/params?numbers=1,4")
        assert [p["number"] for p in listed.json()["params"]] == [1, 4]
        described = one(f"{PREFIX}/drives/cfw11/params?describe")
        body = described.json()
        assert body["writable"] == [100, 101] and body["state"]["id"] == "cfw11"
        assert {r["number"] for r in body["table"]} >= {100, 101, 134}
        bad = one(f"{PREFIX}/drives/cfw11/params?numbers=x")
        assert not bad.ok and "not a parameter number" in bad.json()["error"]
        none = one(f"{PREFIX}/drives/mcd600/params")
        assert not none.ok and "no parameter table" in none.json()["error"]
    finally:
        client.close()


def test_no_gateway_is_exit_3(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "gateway", "params", "backup", "d1", "--connect"]
    out = subprocess.run(
        [*argv, zenoh_endpoint(), "-o", str(tmp_path / "x.json")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert out.returncode == 3 and "no gateway answers" in out.stderr
