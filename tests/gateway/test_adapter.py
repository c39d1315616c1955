"""The adapter table: name -> "module:Class", imported only when a config names it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.adapter import DriveAdapter
from gateway.config import ADAPTERS, BusConfig, adapter_names, load_adapter
from gateway.errors import AdapterError
from tests.support.fake_adapter import FakeAdapter, FakeBusOptions

ROOT = Path(__file__).resolve().parents[2]


def test_the_table_names_classes_as_strings() -> None:
    assert set(ADAPTERS) == {"profibus", "devicenet", "canopen"}
    for target in ADAPTERS.values():
        module, _, cls = target.partition(":")
        assert module.startswith("adapters.") and cls.isidentifier()


def test_the_core_imports_no_adapter_until_one_is_loaded() -> None:
    probe = (
        "import json, sys\n"
        "import gateway.cli, gateway.config, gateway.runtime.daemon, gateway.hub\n"
        "import gateway.zenoh.frontend, gateway.modbus.frontend\n"
        # pyserial is imported by pymodbus itself (its serial transports), not by the core
        "before = sorted(m for m in sys.modules if m.split('.')[0] in ('adapters', 'can', 'canopen'))\n"
        "from gateway.config import load_adapter\n"
        "cls = load_adapter('profibus')\n"
        "after = 'adapters.profibus.adapter' in sys.modules\n"
        "print(json.dumps([before, after, cls.__module__]))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    before, after, module = json.loads(out.stdout)
    assert before == []
    assert after and module == "adapters.profibus.adapter"


@pytest.mark.parametrize("name", sorted(ADAPTERS))
def test_every_registered_adapter_has_the_class_side(name: str) -> None:
    cls = load_adapter(name)
    assert cls.devices and len(cls.address_range) == 2
    assert callable(cls.parse_bus_options) and callable(cls.parse_drive_options)


def test_an_installed_entry_point_loads_a_third_party_adapter() -> None:
    # tests/support/plugins.py declares the fake adapter as a distribution would
    assert "fake" in adapter_names()
    cls = load_adapter("fake")
    assert cls is FakeAdapter
    adapter = FakeAdapter(BusConfig(name="x", adapter="fake", options=FakeBusOptions()))
    assert isinstance(adapter, DriveAdapter)


NOT_A_NAME = (
    "is not an adapter name: a config names a registered adapter (canopen, devicenet, echo-profibus, fake, held, "
    "profibus), never a module; a third-party adapter is installed as an entry point "
    "in the group 'drive_gateway.adapters'"
)


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("canbus", "unknown adapter 'canbus' (known: canopen, devicenet, echo-profibus, fake, held, profibus)"),
        ("profibu", "unknown adapter 'profibu' (known: canopen, devicenet, echo-profibus, fake, held, profibus); did you mean 'profibus'?"),
        ("", "unknown adapter '' (known: canopen, devicenet, echo-profibus, fake, held, profibus)"),
        (":x", f"':x' {NOT_A_NAME}"),
        (".x:y", f"'.x:y' {NOT_A_NAME}"),
        ("os:getcwd", f"'os:getcwd' {NOT_A_NAME}"),
        ("json:loads", f"'json:loads' {NOT_A_NAME}"),
        ("tests.support.fake_adapter:FakeAdapter", f"'tests.support.fake_adapter:FakeAdapter' {NOT_A_NAME}"),
        ("adapters.profibus.adapter:ProfibusAdapter", f"'adapters.profibus.adapter:ProfibusAdapter' {NOT_A_NAME}"),
    ],
)  # fmt: skip
def test_load_errors_say_what_is_wrong(name: str, message: str) -> None:
    with pytest.raises(AdapterError) as err:
        load_adapter(name)
    assert str(err.value) == message


def test_param_info_scales_and_names() -> None:
    from gateway.adapter import ParamInfo, param_table

    accel = ParamInfo(100, "Acceleration time", "s", 1, 0.0, 999.0, code="P0100")
    assert (accel.label, accel.scaled(20), accel.scaled(85)) == ("P0100", 2.0, 8.5)
    assert ParamInfo(3, "Motor current", "A", 1).label == "P3"
    assert ParamInfo(23, "Software version", "", 2).scaled(500) == 5.0
    assert ParamInfo(227, "Run/stop").scaled(4) == 4  # an int stays an int
    # what an EDS may give besides decimal places: multiplier and offset
    assert ParamInfo(5, "Temperature", "C", 0, multiplier=0.5, offset=-10).scaled(50) == 20.0
    table = param_table([accel])
    assert table[100] is accel and 101 not in table
    with pytest.raises(ValueError, match="listed twice"):
        param_table([accel, accel])
    with pytest.raises(TypeError):
        table[101] = accel  # type: ignore[index]


def test_a_module_path_in_a_config_is_never_imported(tmp_path: Path) -> None:
    """``check-config`` run from a folder holding evilmod.py used to import (run) it."""
    marker = tmp_path / "ran"
    (tmp_path / "evilmod.py").write_text(
        f"open({str(marker)!r}, 'w').close()\nclass Evil:\n    pass\n"
    )
    cfg = tmp_path / "site.toml"
    cfg.write_text(
        "[buses.l]\nadapter = 'evilmod:Evil'\n"
        "[[buses.l.drives]]\nid = 'a'\ndevice = 'CFW-11'\naddress = 1\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for command in ("check-config", "run"):
        argv = [command, str(cfg)] if command == "check-config" else [command, "--config", str(cfg)]
        out = subprocess.run(
            [sys.executable, "-m", "gateway", *argv],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert out.returncode == 2, out.stderr
        assert "'evilmod:Evil' is not an adapter name" in out.stderr
        assert "Traceback" not in out.stderr
        assert not marker.exists()
