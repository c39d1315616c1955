"""The echo test slave is not a drive: no configured line takes it (docs/safety.md)."""

from __future__ import annotations

from pathlib import Path

import pytest

from gateway.config import load
from gateway.errors import ConfigErrors
from gateway.model import Device

LINES = {
    "profibus": "port = '/dev/null'\n",
    "devicenet": "channel = 'x'\ninterface = 'virtual'\n",
    "canopen": "channel = 'x'\ninterface = 'virtual'\n",
}


@pytest.mark.parametrize("bus", sorted(LINES))
def test_no_bus_takes_the_echo_test_slave_as_a_drive(bus: str, tmp_path: Path) -> None:
    assert Device.TEST.spec.test
    site = tmp_path / "site.toml"
    site.write_text(
        f"[buses.l]\nadapter = '{bus}'\n{LINES[bus]}"
        "[[buses.l.drives]]\nid = 'e1'\ndevice = 'test'\naddress = 5\n"
    )
    with pytest.raises(ConfigErrors, match=r"buses\.l\.drives\[e1\]\.device: 'test' is not one of"):
        load(site)
