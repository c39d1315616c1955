"""The server's security: its modes, and its certificate written at first start.

``security`` of ``[opcua]`` chooses the endpoints: ``none`` (loopback only, checked with
the config), ``sign`` and ``sign_and_encrypt`` (Basic256Sha256). The signed modes need
the server's application instance certificate: when neither ``certificate`` nor
``private_key`` exists, a self-signed pair is written (RSA 2048, SHA-256, ten years, the
application URI and the host's name in its subject alternative names; the key readable by
the gateway's user only). A client trusts it once (docs/operations.md, "OPC UA server");
with ``trusted_clients`` the server trusts only the client certificates of that folder;
a pair with one half missing is refused rather than silently replaced, since a new
certificate would make every client that trusted the old one refuse the server.
"""

from __future__ import annotations

import logging
import os
import socket
from pathlib import Path

from asyncua import Server, ua
from asyncua.crypto.cert_gen import (
    dump_private_key_as_pem,
    generate_private_key,
    generate_self_signed_app_certificate,
)
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from cryptography import x509
from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives.serialization import Encoding
from cryptography.x509.oid import ExtendedKeyUsageOID

from gateway.errors import StartupError
from gateway.opcuaconfig import OpcuaSection, OpcuaSecurity

log = logging.getLogger(__name__)

CERT_DAYS = 3650
POLICIES: dict[OpcuaSecurity, ua.SecurityPolicyType] = {
    OpcuaSecurity.NONE: ua.SecurityPolicyType.NoSecurity,
    OpcuaSecurity.SIGN: ua.SecurityPolicyType.Basic256Sha256_Sign,
    OpcuaSecurity.SIGN_AND_ENCRYPT: ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
}


def policies(section: OpcuaSection) -> list[ua.SecurityPolicyType]:
    return [POLICIES[mode] for mode in section.security]


def ensure_certificate(section: OpcuaSection, app_uri: str) -> tuple[Path, Path] | None:
    """The certificate and key paths of a server with signed modes (written when both are
    absent); None when it offers ``none`` only. StartupError when they cannot be."""
    cert, key = section.certificate, section.private_key
    if cert is None or key is None:
        return None
    have_cert, have_key = cert.is_file(), key.is_file()
    if have_cert and have_key:
        return cert, key
    if have_cert or have_key:
        missing = key if have_cert else cert
        raise StartupError(
            "opcua",
            f"{missing} is missing while its other half exists",
            "restore it, or remove both certificate and private_key to have a new pair "
            "written (every client must then trust the new certificate)",
        )
    try:
        write_certificate(cert, key, app_uri)
    except OSError as exc:
        raise StartupError(
            "opcua",
            f"cannot write the server certificate {cert}: {(exc.strerror or str(exc)).lower()}",
            "make its folder writable by the gateway's user, or set [opcua] certificate",
        ) from None
    return cert, key


def write_certificate(cert: Path, key: Path, app_uri: str) -> None:
    """A new self-signed application instance certificate (DER) and its key (PEM, 0600)."""
    host = socket.gethostname() or "localhost"
    private = generate_private_key()
    certificate = generate_self_signed_app_certificate(
        private,
        f"drive-gateway@{host}",
        {"organizationName": "drive-gateway"},
        [x509.UniformResourceIdentifier(app_uri), x509.DNSName(host), x509.DNSName("localhost")],
        extended=[ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
        days=CERT_DAYS,
    )
    key.parent.mkdir(parents=True, exist_ok=True)
    cert.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(key, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(dump_private_key_as_pem(private))
    cert.write_bytes(certificate.public_bytes(Encoding.DER))
    log.warning(
        "OPC UA: wrote a new self-signed server certificate %s (SHA-1 thumbprint %s) and key "
        "%s; clients must trust it once",
        cert,
        thumbprint(cert),
        key,
    )


def thumbprint(cert: Path) -> str:
    """The certificate's SHA-1 thumbprint, as OPC UA clients show it."""
    loaded = x509.load_der_x509_certificate(cert.read_bytes())
    return loaded.fingerprint(hashes.SHA1()).hex()


async def trust_clients(server: Server, section: OpcuaSection) -> int | None:
    """With ``trusted_clients``: only the client certificates of that folder (or signed by a
    CA in it), in their validity, with the OPC UA key usages, are admitted; returns how many
    certificates the folder holds (None without a trust list). StartupError when the folder
    is not one."""
    folder = section.trusted_clients
    if folder is None:
        return None
    if not folder.is_dir():
        raise StartupError(
            "opcua",
            f"trusted_clients {folder} is not a folder",
            "create it and put the trusted client certificates in it, or remove the key",
        )
    store = TrustStore([folder], [])
    await store.load()
    options = (
        CertificateValidatorOptions.TRUSTED_VALIDATION | CertificateValidatorOptions.PEER_CLIENT
    )
    server.set_certificate_validator(CertificateValidator(options, store).validate)
    return sum(1 for p in folder.iterdir() if p.is_file())
