"""The [opcua] table: on in the demo, off in a site that does not ask for it, and the
security a network-facing server may not have refused with one clear line."""

from __future__ import annotations

from pathlib import Path

import pytest

from gateway.config import DEFAULT_CONFIG, load
from gateway.errors import ConfigErrors
from gateway.opcuaconfig import OpcuaSecurity, is_loopback


def write(tmp_path: Path, opcua: str) -> Path:
    path = tmp_path / "site.toml"
    path.write_text(f"[gateway]\nname = 't'\n{opcua}")
    return path


def errors(tmp_path: Path, opcua: str) -> list[str]:
    with pytest.raises(ConfigErrors) as err:
        load(write(tmp_path, opcua))
    return [str(e).replace(str(tmp_path) + "/", "") for e in err.value.errors]


def test_the_demo_serves_opcua_on_loopback_with_security_none() -> None:
    section = load(DEFAULT_CONFIG).opcua
    assert section.enabled
    assert section.endpoint == "opc.tcp://127.0.0.1:4840/drive-gateway"
    assert section.security == (OpcuaSecurity.NONE,)


def test_a_site_without_the_table_serves_no_opcua(tmp_path: Path) -> None:
    assert not load(write(tmp_path, "")).opcua.enabled
    assert not load(
        write(tmp_path, "[opcua]\nbind = '127.0.0.1:4841'\nenabled = false\n")
    ).opcua.enabled


def test_a_signed_server_on_the_network(tmp_path: Path) -> None:
    section = load(
        write(
            tmp_path,
            "[opcua]\nbind = '0.0.0.0:4840'\nsecurity = ['sign_and_encrypt', 'sign']\n"
            "certificate = 'pki/server.der'\nprivate_key = 'pki/server.pem'\n"
            "publish_interval = 0.25\nmax_sessions = 8\n",
        )
    ).opcua
    assert section.enabled and section.host == "0.0.0.0"
    assert section.security == (OpcuaSecurity.SIGN_AND_ENCRYPT, OpcuaSecurity.SIGN)
    assert section.certificate == tmp_path / "pki" / "server.der"  # relative to the file
    assert (section.publish_interval, section.max_sessions) == (0.25, 8)


def test_the_per_session_limits(tmp_path: Path) -> None:
    default = load(write(tmp_path, "[opcua]\nbind = '127.0.0.1:4840'\n")).opcua
    # a SCADA subscribes to every drive's readings: 220 drives x ~10 items fit by default
    assert (default.max_subscriptions, default.max_monitored_items) == (20, 10_000)
    assert default.min_publishing_interval == 0.05
    section = load(
        write(
            tmp_path,
            "[opcua]\nbind = '127.0.0.1:4840'\nmax_subscriptions = 4\n"
            "max_monitored_items = 500\nmin_publishing_interval = 0.25\n",
        )
    ).opcua
    assert (section.max_subscriptions, section.max_monitored_items) == (4, 500)
    assert section.min_publishing_interval == 0.25


def test_security_none_is_refused_off_loopback(tmp_path: Path) -> None:
    assert errors(tmp_path, "[opcua]\nbind = '0.0.0.0:4840'\n") == [
        'site.toml: opcua.security: "none" is refused on 0.0.0.0, which is not a loopback '
        "address: any client on the network could read and command the drives "
        'unauthenticated; offer only "sign" and "sign_and_encrypt" there, or bind 127.0.0.1'
    ]


@pytest.mark.parametrize(
    ("table", "message"),
    [
        (
            "bind = '127.0.0.1:4840'\nsecurity = ['sign']\n",
            "site.toml: opcua.certificate: the signed modes need the server's certificate: give "
            "certificate and private_key (both are written at first start when absent)",
        ),
        (
            "bind = '127.0.0.1:4840'\ncertificate = 'a.der'\n",
            "site.toml: opcua.private_key: give certificate and private_key together",
        ),
        (
            "bind = '127.0.0.1:4840'\nsecurity = ['basic128']\n",
            "site.toml: opcua.security[0]: 'basic128' is not one of 'none', 'sign', "
            "'sign_and_encrypt'",
        ),
        (
            "bind = 'localhost'\n",
            "site.toml: opcua.bind: 'localhost' is not HOST:PORT (like 127.0.0.1:4840)",
        ),
        ("bind = '127.0.0.1:99999'\n", "site.toml: opcua.bind: port 99999 is not 0-65535"),
        (
            "bind = '127.0.0.1:4840'\npublish_interval = 0.001\n",
            "site.toml: opcua.publish_interval: 0.001 is below the minimum 0.02",
        ),
        ("bind = '127.0.0.1:4840'\nport = 4840\n", "site.toml: opcua.port: unknown key"),
        (
            "bind = '127.0.0.1:4840'\nmax_subscriptions = 0\n",
            "site.toml: opcua.max_subscriptions: 0 is below the minimum 1",
        ),
        (
            "bind = '127.0.0.1:4840'\nmax_subscriptions = 2.5\n",
            "site.toml: opcua.max_subscriptions: must be an integer, not a number",
        ),
        (
            "bind = '127.0.0.1:4840'\nmax_monitored_items = '10k'\n",
            "site.toml: opcua.max_monitored_items: must be an integer, not a string",
        ),
        (
            "bind = '127.0.0.1:4840'\nmax_monitored_items = 2000000\n",
            "site.toml: opcua.max_monitored_items: 2000000 is above the maximum 1000000",
        ),
        (
            "bind = '127.0.0.1:4840'\nmin_publishing_interval = 0.001\n",
            "site.toml: opcua.min_publishing_interval: 0.001 is below the minimum 0.01",
        ),
        (
            "bind = '127.0.0.1:4840'\nmin_publishing_interval = true\n",
            "site.toml: opcua.min_publishing_interval: must be a number, not a boolean",
        ),
        (
            "bind = '127.0.0.1:4840'\ntrusted_clients = 'trusted'\n",
            'site.toml: opcua.trusted_clients: a trust list needs a signed mode ("sign", '
            '"sign_and_encrypt")',
        ),
    ],
)
def test_a_bad_opcua_table_says_what_is_wrong(tmp_path: Path, table: str, message: str) -> None:
    assert errors(tmp_path, f"[opcua]\n{table}") == [message]


def test_loopback_names() -> None:
    assert is_loopback("127.0.0.1") and is_loopback("127.3.4.5") and is_loopback("::1")
    assert is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("10.0.0.5")
    assert not is_loopback("edge-box.plant.example")
