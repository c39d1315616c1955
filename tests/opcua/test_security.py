"""The server's security through a real daemon: a signed and encrypted server writes its
certificate at first start, keeps it across restarts, takes a Basic256Sha256 client and
refuses one without security; a certificate missing its key stops the start."""

from __future__ import annotations

import asyncio
import stat
from pathlib import Path

import pytest
from asyncua import Client, ua
from cryptography import x509

from gateway.config import load
from gateway.errors import StartupError
from gateway.opcua.security import ensure_certificate, write_certificate
from gateway.opcuaconfig import OpcuaSection, OpcuaSecurity
from gateway.runtime.daemon import EXIT_STARTUP, Daemon
from gateway.runtime.systemd import Notifier
from tests.opcua.harness import TIMEOUT, config_text, running_gateway
from tests.support.net import free_port

SIGNED = '["sign_and_encrypt", "sign"]'
PKI = 'certificate = "pki/server.der"\nprivate_key = "pki/server.pem"\n'


def signed_section(tmp_path: Path) -> OpcuaSection:
    return OpcuaSection(
        enabled=True,
        security=(OpcuaSecurity.SIGN,),
        certificate=tmp_path / "pki" / "server.der",
        private_key=tmp_path / "pki" / "server.pem",
    )


def test_the_certificate_is_written_once_with_a_private_key(tmp_path: Path) -> None:
    section = signed_section(tmp_path)
    cert, key = ensure_certificate(section, "urn:drive-gateway:t") or (None, None)
    assert cert is not None and key is not None
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
    loaded = x509.load_der_x509_certificate(cert.read_bytes())
    names = loaded.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "urn:drive-gateway:t" in names.get_values_for_type(x509.UniformResourceIdentifier)
    before = cert.read_bytes()
    assert ensure_certificate(section, "urn:drive-gateway:t") == (cert, key)
    assert cert.read_bytes() == before  # kept: the clients trusted this one
    key.unlink()
    with pytest.raises(StartupError, match=r"server\.pem is missing while its other half exists"):
        ensure_certificate(section, "urn:drive-gateway:t")
    assert ensure_certificate(OpcuaSection(enabled=True), "urn:x") is None


async def test_a_signed_server_takes_basic256sha256_and_refuses_no_security(
    tmp_path: Path,
) -> None:
    client_cert, client_key = tmp_path / "client.der", tmp_path / "client.pem"
    write_certificate(client_cert, client_key, "urn:drive-gateway:test-client")
    async with running_gateway(tmp_path, security=SIGNED, extra=PKI) as gw:
        assert (tmp_path / "pki" / "server.der").is_file()
        plain = Client(gw.endpoint, timeout=TIMEOUT)
        endpoints = await plain.connect_and_get_server_endpoints()
        modes = {(e.SecurityPolicyUri.rsplit("#")[-1], e.SecurityMode.name) for e in endpoints}
        assert modes == {("Basic256Sha256", "SignAndEncrypt"), ("Basic256Sha256", "Sign")}
        with pytest.raises(ua.UaError):
            async with Client(gw.endpoint, timeout=TIMEOUT) as none:
                await none.get_node(ua.NodeId("m1.Device", 2)).read_value()
        secure = Client(gw.endpoint, timeout=TIMEOUT)
        secure.application_uri = "urn:drive-gateway:test-client"
        await secure.set_security_string(
            f"Basic256Sha256,SignAndEncrypt,{client_cert},{client_key}"
        )
        async with secure:
            assert await secure.get_node(ua.NodeId("m1.Device", 2)).read_value() == "test"


async def test_a_certificate_without_its_key_stops_the_start(tmp_path: Path) -> None:
    (tmp_path / "pki").mkdir()
    (tmp_path / "pki" / "server.der").write_bytes(b"left alone")
    cfg = tmp_path / "gateway.toml"
    cfg.write_text(config_text(free_port(), security=SIGNED, extra=PKI))
    daemon = Daemon(load(cfg), notifier=Notifier({}))
    assert await daemon.run() == EXIT_STARTUP
    await asyncio.get_running_loop().shutdown_default_executor()  # asyncua's start-up thread
    assert isinstance(daemon.fatal, StartupError)
    assert "server.pem is missing while its other half exists" in str(daemon.fatal)
    assert (tmp_path / "pki" / "server.der").read_bytes() == b"left alone"


async def test_a_trust_list_admits_its_clients_only(tmp_path: Path) -> None:
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    known = (tmp_path / "known.der", tmp_path / "known.pem")
    stranger = (tmp_path / "stranger.der", tmp_path / "stranger.pem")
    write_certificate(*known, "urn:drive-gateway:known")
    write_certificate(*stranger, "urn:drive-gateway:stranger")
    (trusted / "known.der").write_bytes(known[0].read_bytes())
    extra = PKI + 'trusted_clients = "trusted"\n'
    async with running_gateway(tmp_path, security=SIGNED, extra=extra) as gw:

        async def device(pair: tuple[Path, Path], uri: str) -> str:
            client = Client(gw.endpoint, timeout=TIMEOUT)
            client.application_uri = uri
            await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{pair[0]},{pair[1]}")
            async with client:
                value: str = await client.get_node(ua.NodeId("m1.Device", 2)).read_value()
                return value

        assert await device(known, "urn:drive-gateway:known") == "test"
        with pytest.raises((ua.UaError, ConnectionError, TimeoutError)):
            await device(stranger, "urn:drive-gateway:stranger")


async def test_sessions_beyond_max_sessions_are_refused(tmp_path: Path) -> None:
    async with running_gateway(tmp_path, extra="max_sessions = 1\n") as gw:
        async with Client(gw.endpoint, timeout=TIMEOUT) as first:
            with pytest.raises(ua.UaError):
                async with Client(gw.endpoint, timeout=TIMEOUT) as second:
                    await second.get_node(ua.NodeId("m1.Device", 2)).read_value()
            assert await first.get_node(ua.NodeId("m1.Device", 2)).read_value() == "test"
        front_end = gw.daemon.front_ends["opcua"]
        counted = front_end.counted()
        assert counted.connections_over_limit == 1
        # the first session closed: a new one is admitted
        async with Client(gw.endpoint, timeout=TIMEOUT) as third:
            assert await third.get_node(ua.NodeId("m1.Device", 2)).read_value() == "test"
