"""The ``[web]`` table: what it turns on, and every mistake named with file, key and reason."""

from __future__ import annotations

import ipaddress
import socket
from pathlib import Path

import pytest

from gateway.config import DEFAULT_CONFIG, load
from gateway.errors import ConfigError, ConfigErrors, StartupError
from gateway.webconfig import LOOPBACK, WebLimits
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
            f'[[users]]\nname = "ana"\nrole = "operator"\ntoken_sha256 = "{"1" * 64}"',
        )
    ).web
    assert (web.enabled, web.host, web.port, web.commands) == (True, "0.0.0.0", 8081, True)
    assert web.allow == (ipaddress.ip_network("10.1.0.0/16"), ipaddress.ip_network("::1"))
    assert web.token_sha256 is None
    local = load(write(tmp_path, f'commands = true\ntoken_sha256 = "{TOKEN_SHA256}"')).web
    assert local.token_sha256 == TOKEN_SHA256  # a page on this machine only


@pytest.mark.parametrize(
    ("web", "message"),
    [
        ('bind = "8080"', "web.bind: '8080' is not HOST:PORT (like 127.0.0.1:8080)"),
        ('bind = "h:99999"', "web.bind: port 99999 is not 0-65535"),
        ("allow = []", "web.allow: an empty list refuses everyone"),
        ('allow = ["10.0.0.0/33"]', "web.allow[0]: '10.0.0.0/33' is not an address or CIDR"),
        ("commands = true", "web.commands: commands = true needs [[users]]"),
        (
            'allow = ["10.0.0.0/8"]\ncommands = true',
            "web.commands: commands = true on a page other machines reach needs [[users]]",
        ),
        (
            f'allow = ["10.0.0.0/8"]\ntoken_sha256 = "{TOKEN_SHA256}"',
            "web.token_sha256: a shared token names no one: it is for a page on this machine",
        ),
        ('anonymous = "guest"', 'web.anonymous: \'guest\' is not "viewer" or "none"'),
        ('tls_cert = "c.pem"', "web.tls_key: give tls_cert and tls_key both"),
        ('token_sha256 = "abc"', "web.token_sha256: must be 64 lower-case hex digits"),
        ("names = []", "web.names: give 1 to 64 names users reach the page by"),
        ('names = ["gw:8080"]', "web.names[0]: 'gw:8080' is not a host name or address, with"),
        ('names = ["gw", "http://gw"]', "web.names[1]: 'http://gw' is not a host name or"),
        ('names = ["*.plant.example"]', "web.names[0]: '*.plant.example' is not a host name"),
        ('names = "gw"', "web.names: must be an array of strings, not a string"),
        ("comands = true", "web.comands: unknown key (did you mean 'commands'?)"),
        ("commands = 1", "web.commands: must be true or false, not an integer"),
        ("max_connections = 0", "web.max_connections: 0 is below the minimum 1"),
        (
            "max_connections = 10\nmax_connections_per_peer = 20",
            "web.max_connections_per_peer: 20 is above max_connections (10): one address",
        ),
        (
            "max_pages = 200",
            "web.max_pages: 200 is above max_connections (128): every page holds a connection",
        ),
        (
            "max_pages = 10\nmax_pages_per_peer = 11",
            "web.max_pages_per_peer: 11 is above max_pages (10)",
        ),
        ("header_timeout = 0", "web.header_timeout: must be above 0 s, not 0"),
        ("body_timeout = -1.5", "web.body_timeout: must be above 0 s, not -1.5"),
        ("page_send_budget_kib = 8", "web.page_send_budget_kib: 8 is below the minimum 16"),
        ("token_failures = 0", "web.token_failures: 0 is below the minimum 1"),
        ("metrics_max_age = 0.1", "web.metrics_max_age: 0.1 is below the minimum 0.5"),
        ('header_timeout = "10"', "web.header_timeout: must be a number, not a string"),
    ],
)
def test_every_mistake_is_named(tmp_path: Path, web: str, message: str) -> None:
    found = errors_of(tmp_path, web)
    assert len(found) == 1 and found[0].startswith(message), found


def test_the_admission_limits_by_default_and_as_given(tmp_path: Path) -> None:
    assert load(write(tmp_path, "")).web.limits == WebLimits()
    limits = WebLimits()
    assert (limits.max_connections, limits.max_connections_per_peer) == (128, 64)
    assert (limits.max_pages, limits.max_pages_per_peer) == (48, 24)
    assert (limits.header_timeout, limits.body_timeout, limits.metrics_max_age) == (10, 10, 0.5)
    assert limits.page_send_budget == 512 * 1024
    given = load(
        write(
            tmp_path,
            "max_connections = 20\nmax_connections_per_peer = 4\nheader_timeout = 2.5\n"
            "body_timeout = 3\nmax_pages = 6\nmax_pages_per_peer = 2\n"
            "page_send_budget_kib = 64\ntoken_failures = 3\ntoken_window = 300\n"
            "metrics_max_age = 5",
        )
    ).web.limits
    assert given == WebLimits(20, 4, 2.5, 3.0, 6, 2, 64, 3, 300.0, 5.0)


def test_a_lower_connection_limit_lowers_the_page_limits_left_out(tmp_path: Path) -> None:
    limits = load(write(tmp_path, "max_connections = 10")).web.limits
    assert (limits.max_connections_per_peer, limits.max_pages, limits.max_pages_per_peer) == (
        10,
        10,
        10,
    )


def test_the_host_names_by_default_and_as_given(tmp_path: Path) -> None:
    loopback = {"localhost", "127.0.0.1", "[::1]"}
    demo = load(DEFAULT_CONFIG).web
    assert demo.names is None and demo.host_names == loopback  # the browser test's URL
    assert load(write(tmp_path, 'bind = "[::1]:8080"')).web.host_names == loopback
    assert load(write(tmp_path, 'bind = "0.0.0.0:8080"')).web.host_names == loopback
    assert load(write(tmp_path, 'bind = "10.1.2.3:8080"')).web.host_names == {
        *loopback,
        "10.1.2.3",
    }
    given = load(
        write(tmp_path, 'bind = "0.0.0.0:8080"\nnames = ["Edge-Box-3.", "FE80::1", "edge-box-3"]')
    ).web
    assert given.names == ("edge-box-3", "[fe80::1]")
    assert given.host_names == {"edge-box-3", "[fe80::1]"}
    moved = load(write(tmp_path, "")).with_overrides(web_bind="10.9.8.7:0").web
    assert moved.host_names == {*loopback, "10.9.8.7"}


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
