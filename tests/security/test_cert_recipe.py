"""The openssl recipe of docs/operations.md ("Certificates"), run as written, and its
files used with the shipped config/zenoh-secure.json5 (in-process Zenoh sessions)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from tests.security.pki import Identity
from tests.security.test_zenoh_acl import PREFIX, Scada, secure_config_text, session_config
from tests.support.net import free_port

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "operations.md"
MARKER = "<!-- the block below is run by tests/security/test_cert_recipe.py -->"

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="no openssl CLI")


def recipe() -> str:
    text = DOC.read_text(encoding="utf-8")
    after = text.split(MARKER, 1)[1]
    fence = "```sh\n"
    assert after.lstrip("\n").startswith(fence), "the marker must precede the sh block"
    return after.split(fence, 1)[1].split("```", 1)[0]


@pytest.fixture(scope="module")
def tls_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("recipe") / "tls"
    env = {**os.environ, "DIR": str(out), "GW_SAN": "IP:127.0.0.1,DNS:localhost", "DAYS": "2"}
    proc = subprocess.run(
        ["sh", "-c", recipe()], env=env, capture_output=True, text=True, check=False, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    return out


def load(path: Path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def test_the_recipe_makes_what_the_config_and_the_doc_name(tls_dir: Path) -> None:
    names = {p.name for p in tls_dir.iterdir()}
    wanted = {"ca.pem", "ca.key", "gateway.pem", "gateway.key"}
    wanted |= {f"scada-{r}.{x}" for r in ("readonly", "operator") for x in ("pem", "key")}
    assert wanted <= names
    assert not {n for n in names if n.endswith((".csr", ".ext"))}
    assert all((tls_dir / n).stat().st_mode & 0o077 == 0 for n in names if n.endswith(".key"))
    ca = load(tls_dir / "ca.pem")
    for name, usages in {
        "gateway": {ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH},
        "scada-readonly": {ExtendedKeyUsageOID.CLIENT_AUTH},
        "scada-operator": {ExtendedKeyUsageOID.CLIENT_AUTH},
    }.items():
        cert = load(tls_dir / f"{name}.pem")
        cert.verify_directly_issued_by(ca)
        cn = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value
        assert cn == name
        eku = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
        assert set(eku) == usages
    san = load(tls_dir / "gateway.pem").extensions.get_extension_for_class(
        x509.SubjectAlternativeName
    )
    assert "127.0.0.1" in {str(ip) for ip in san.value.get_values_for_type(x509.IPAddress)}
    assert (tls_dir / "gateway.key").read_text().startswith("-----BEGIN PRIVATE KEY-----")


@pytest.fixture
def gateway_like(tls_dir: Path, tmp_path: Path) -> Iterator[str]:
    """A Zenoh peer on the shipped config with the recipe's files, serving the health and a
    command key the way the gateway does (queryables)."""
    port = free_port()
    path = tmp_path / "zenoh-secure.json5"
    path.write_text(secure_config_text(tls_dir, port))
    session = zenoh.open(zenoh.Config.from_file(str(path)))
    try:

        def answer(query: zenoh.Query) -> None:
            query.reply(query.key_expr, json.dumps({"ok": True}).encode())

        queryables = [
            session.declare_queryable(f"{PREFIX}/gateway/health", answer),
            session.declare_queryable(f"{PREFIX}/drives/*/command", answer),
        ]
        yield f"tls/127.0.0.1:{port}"
        for q in queryables:
            q.undeclare()
    finally:
        session.close()


@pytest.mark.parametrize(
    ("name", "commands"), [("scada-readonly", False), ("scada-operator", True)]
)
def test_the_recipe_identities_get_their_rights(
    tls_dir: Path, gateway_like: str, name: str, commands: bool
) -> None:
    identity = Identity(name, tls_dir / f"{name}.pem", tls_dir / f"{name}.key")
    client = Scada(session_config(gateway_like, tls_dir / "ca.pem", identity))
    try:
        assert client.one(f"{PREFIX}/gateway/health").ok
        replies = client.query(f"{PREFIX}/drives/d1/command", {"run": True})
        assert len(replies) == (1 if commands else 0)
    finally:
        client.close()
