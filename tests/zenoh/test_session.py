"""The session config: explicit endpoints, no scouting, a config file passed as it is."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import zenoh

from gateway.config import ZenohSection
from gateway.errors import ConfigError
from gateway.zenoh.session import config_document, zenoh_config
from tests.support.net import free_port


def test_the_document_names_endpoints_and_turns_scouting_off() -> None:
    section = ZenohSection(listen=("tcp/127.0.0.1:7447",), connect=("tcp/127.0.0.1:7448",))
    assert config_document(section) == {
        "mode": "peer",
        "listen": {"endpoints": ["tcp/127.0.0.1:7447"]},
        "connect": {"endpoints": ["tcp/127.0.0.1:7448"]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"shared_memory": {"enabled": False}},  # issue 18
    }
    on = config_document(ZenohSection(multicast_scouting=True, mode="client"))
    assert on["mode"] == "client"
    assert on["scouting"] == {"multicast": {"enabled": True}, "gossip": {"enabled": True}}


def test_zenoh_takes_the_config_as_given() -> None:
    section = ZenohSection(listen=(), connect=("tcp/127.0.0.1:7448",))
    conf = zenoh_config(section)
    assert json.loads(conf.get_json("listen/endpoints")) == []
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7448"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("scouting/gossip/enabled")) is False
    assert json.loads(conf.get_json("mode")) == "peer"


def test_a_config_file_is_passed_as_it_is(tmp_path: Path) -> None:
    file = tmp_path / "zenoh.json5"
    file.write_text(
        "// a site's own Zenoh config\n"
        "{ mode: 'client', connect: { endpoints: ['tcp/127.0.0.1:7999'] },\n"
        "  scouting: { multicast: { enabled: false } } }\n"
    )
    conf = zenoh_config(ZenohSection(config_file=file, listen=("tcp/127.0.0.1:1",)))
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7999"]


def test_a_bad_config_file_is_a_config_error_naming_it(tmp_path: Path) -> None:
    file = tmp_path / "zenoh.json5"
    file.write_text("{ bogus_key: 1 }")
    with pytest.raises(ConfigError) as exc:
        zenoh_config(ZenohSection(config_file=file))
    assert str(exc.value).startswith(f"{file}: not a Zenoh config: ")
    assert "bogus_key" in str(exc.value)


def _sockets() -> dict[str, tuple[str, str, str]]:
    """This process's sockets: inode -> (table, local address, state)."""
    inodes = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = {}
    for table in ("tcp", "tcp6", "udp", "udp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            cols = line.split()
            if cols[9] in inodes:
                found[cols[9]] = (table, cols[1], cols[3])
    return found


def test_a_session_listens_only_where_told_and_sends_no_scouting() -> None:
    port = free_port()
    before = _sockets()
    session = zenoh.open(zenoh_config(ZenohSection(listen=(f"tcp/127.0.0.1:{port}",))))
    try:
        new = [v for k, v in _sockets().items() if k not in before]
    finally:
        session.close()
    # one TCP listener on 127.0.0.1:port (0100007F is 127.0.0.1, 0A is LISTEN); no UDP at all
    assert new == [("tcp", f"0100007F:{port:04X}", "0A")]
