"""Password hashes: scrypt from the standard library (``hashlib.scrypt``, OpenSSL's).

A hash line is ``scrypt$<n>$<r>$<p>$<salt>$<key>`` (salt and key in unpadded URL-safe
base64), made by ``drive-gateway users hash`` and written in a ``[[users]]`` table: the
config file never holds a password. The parameters travel with the line, so a hash made
with stronger ones later still verifies; lines whose cost is below :data:`MIN_N` or whose
memory is above :data:`MAX_MEMORY` are refused when the config is read (a weak hash, or one
that would let a login take the gateway's memory). Why these figures:
docs/decisions/0079-roles-users-and-sessions.md.

API tokens are random secrets the gateway makes (``drive-gateway users token``), 32 bytes:
their SHA-256 is enough (nothing to guess from a dictionary), so a request with a token
costs one hash, not a KDF.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import re
import secrets
from dataclasses import dataclass, replace

from gateway.errors import GatewayError

N = 1 << 15  # CPU/memory cost: 2^15
R = 8  # block size
P = 1  # parallelism
SALT_BYTES = 16
KEY_BYTES = 32
MIN_N = 1 << 14
MAX_N = 1 << 20
MAX_MEMORY = 256 << 20  # bytes one verification may take (128 * r * n * p, with headroom)
PREFIX = "scrypt"
TOKEN_BYTES = 32
_SHA256_HEX = re.compile(r"[0-9a-f]{64}")


class BadHash(GatewayError, ValueError):
    """A hash line that is not one this module makes (the reason is the message)."""


@dataclass(frozen=True, slots=True)
class ScryptHash:
    n: int
    r: int
    p: int
    salt: bytes
    key: bytes

    @property
    def memory(self) -> int:
        return 128 * self.r * self.n * self.p

    def line(self) -> str:
        fields = (str(self.n), str(self.r), str(self.p), _b64(self.salt), _b64(self.key))
        return "$".join((PREFIX, *fields))


def _b64(raw: bytes) -> str:
    return base64.urlsafe_b64encode(raw).decode("ascii").rstrip("=")


def _unb64(text: str) -> bytes:
    if not re.fullmatch(r"[A-Za-z0-9_-]+", text):
        raise BadHash("its salt and key are not base64")
    try:
        return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))
    except (binascii.Error, ValueError):
        raise BadHash("its salt and key are not base64") from None


def _derive(password: str, params: ScryptHash) -> bytes:
    """The key of ``password`` with the parameters and salt of ``params``."""
    return hashlib.scrypt(
        password.encode("utf-8", "surrogatepass"),
        salt=params.salt,
        n=params.n,
        r=params.r,
        p=params.p,
        maxmem=params.memory + (1 << 20),
        dklen=len(params.key),
    )


def hash_password(password: str, salt: bytes | None = None, n: int = N) -> ScryptHash:
    """A new hash of ``password`` (a random salt unless given)."""
    salt = secrets.token_bytes(SALT_BYTES) if salt is None else salt
    params = ScryptHash(n, R, P, salt, bytes(KEY_BYTES))
    return replace(params, key=_derive(password, params))


def parse_hash(line: str) -> ScryptHash:
    """The hash a line gives; BadHash naming what is wrong with it."""
    parts = line.strip().split("$")
    if len(parts) != 6 or parts[0] != PREFIX:
        raise BadHash("is not a scrypt$N$r$p$salt$key line (drive-gateway users hash)")
    if not all(x.isascii() and x.isdigit() and len(x) <= 8 for x in parts[1:4]):
        raise BadHash("its N, r and p are not numbers")
    n, r, p = (int(x) for x in parts[1:4])
    if n < MIN_N or n > MAX_N or n & (n - 1):
        raise BadHash(f"its N ({n}) is not a power of 2 from {MIN_N} to {MAX_N}")
    if not 1 <= r <= 32 or not 1 <= p <= 16:
        raise BadHash(f"its r ({r}) or p ({p}) is out of range (r 1-32, p 1-16)")
    made = ScryptHash(n, r, p, _unb64(parts[4]), _unb64(parts[5]))
    if made.memory > MAX_MEMORY:
        raise BadHash(f"it needs {made.memory >> 20} MiB per login; at most {MAX_MEMORY >> 20}")
    if len(made.salt) < 8 or len(made.key) < 16:
        raise BadHash("its salt or key is too short (8 and 16 bytes at least)")
    return made


def verify_password(password: str, stored: ScryptHash) -> bool:
    """Whether ``password`` is the one ``stored`` was made from (a constant-time compare)."""
    return hmac.compare_digest(_derive(password, stored), stored.key)


def new_token() -> str:
    """A new API token (URL-safe text of :data:`TOKEN_BYTES` random bytes)."""
    return secrets.token_urlsafe(TOKEN_BYTES)


def token_digest(token: str) -> str:
    """The hex SHA-256 of a token: what the config holds."""
    return hashlib.sha256(token.strip().encode("utf-8")).hexdigest()


def is_token_digest(text: str) -> bool:
    return bool(_SHA256_HEX.fullmatch(text))
