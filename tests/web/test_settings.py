"""The ``[web]`` table: what it turns on, and every mistake named with file, key and reason."""

from __future__ import annotations

import ipaddress
import socket
from pathlib import Path

import pytest

from gateway.config import DEFAULT_CONFIG, load
from gateway.errors import ConfigError, ConfigErrors, StartupError
from gateway.webconfig import LOOPBACK
from tests.web.harness import ROOT, TOKEN_SHA256, small_gateway, web_section


def write(tmp_path: Path, web: str) -> Path:
    path = tmp_path / "site.toml"
    path.write_text(f"[web]\n{web}\n")
    return path


def errors_of(tmp_path: Path, web: str) -> list[str]:
    with pytest.raises(ConfigErrors) as err:
        load(write(tmp_path, web))
    return [f"{e.key}: {e.reason}" for e in err.value.errors]


def test_the_demo_serves_a_read_only_page_on_loopback() -> None:
    web = load(DEFAULT_CONFIG).web
    assert (web.enabled, web.host, web.port, web.commands) == (True, "127.0.0.1", 8080, False)
    assert {str(net) for net in web.allow} == {str(net) for net in LOOPBACK}


def test_the_site_template_keeps_the_page_off() -> None:
    web = load(ROOT / "config" / "site.example.toml").web
    assert not web.enabled and not web.commands


def test_no_web_table_no_page(tmp_path: Path) -> None:
    path = tmp_path / "site.toml"
    path.write_text("")
    web = load(path).web
    assert not web.enabled and web.allow == LOOPBACK


def test_a_full_web_table(tmp_path: Path) -> None:
    web = load(
        write(
            tmp_path,
            f'bind = "0.0.0.0:8081"\nallow = ["10.1.0.0/16", "::1"]\ncommands = true\n'
            f'token_sha256 = "{TOKEN_SHA256}"',
        )
    ).web
    assert (web.enabled, web.host, web.port, web.commands) == (True, "0.0.0.0", 8081, True)
    assert web.allow == (ipaddress.ip_network("10.1.0.0/16"), ipaddress.ip_network("::1"))
    assert web.token_sha256 == TOKEN_SHA256


@pytest.mark.parametrize(
    ("web", "message"),
    [
        ('bind = "8080"', "web.bind: '8080' is not HOST:PORT (like 127.0.0.1:8080)"),
        ('bind = "h:99999"', "web.bind: port 99999 is not 0-65535"),
        ("allow = []", "web.allow: an empty list refuses everyone"),
        ('allow = ["10.0.0.0/33"]', "web.allow[0]: '10.0.0.0/33' is not an address or CIDR"),
        ("commands = true", "web.commands: commands = true needs token_sha256"),
        ('token_sha256 = "abc"', "web.token_sha256: must be 64 lower-case hex digits"),
        ("comands = true", "web.comands: unknown key (did you mean 'commands'?)"),
        ("commands = 1", "web.commands: must be true or false, not an integer"),
    ],
)
def test_every_mistake_is_named(tmp_path: Path, web: str, message: str) -> None:
    found = errors_of(tmp_path, web)
    assert len(found) == 1 and found[0].startswith(message), found


def test_web_bind_on_the_command_line(tmp_path: Path) -> None:
    config = load(write(tmp_path, "")).with_overrides(web_bind="127.0.0.1:0")
    assert (config.web.enabled, config.web.port) == (True, 0)
    with pytest.raises(ConfigError, match="not HOST:PORT"):
        config.with_overrides(web_bind="nowhere")


async def test_a_port_in_use_is_a_startup_error_naming_the_fix() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(
            StartupError, match=r"web: cannot listen on 127.0.0.1:\d+: the address is in use"
        ):
            async with small_gateway(web_section(port=port)):
                pass
