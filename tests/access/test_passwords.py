"""scrypt hash lines: made, parsed, verified; bad lines refused with the reason."""

from __future__ import annotations

import hashlib

import pytest

from gateway.access.passwords import (
    MIN_N,
    BadHash,
    ScryptHash,
    hash_password,
    is_token_digest,
    new_token,
    parse_hash,
    token_digest,
    verify_password,
)

# RFC 7914, section 12: scrypt("password", "NaCl", N=1024, r=8, p=16, dkLen=64)
RFC_KEY = bytes.fromhex(
    "fdbabe1c9d3472007856e7190d01e9fe7c6ad7cbc8237830e77376634b3731622eaf30d92e22a3886ff109279d9830dac727afb94a83ee6d8360cbdfa2cc0640"
)


def test_verification_is_scrypt_itself() -> None:
    rfc = ScryptHash(1024, 8, 16, b"NaCl", RFC_KEY)
    assert verify_password("password", rfc)
    assert not verify_password("Password", rfc)


def test_a_hash_line_round_trips_and_verifies() -> None:
    made = hash_password("correct horse", n=MIN_N)
    line = made.line()
    assert line.startswith(f"scrypt${MIN_N}$8$1$") and "=" not in line
    parsed = parse_hash(line)
    assert parsed == made
    assert verify_password("correct horse", parsed)
    assert not verify_password("correct horse ", parsed)


def test_the_default_parameters() -> None:
    made = hash_password("pw")
    assert (made.n, made.r, made.p, len(made.salt), len(made.key)) == (1 << 15, 8, 1, 16, 32)
    assert made.memory == 32 << 20
    assert hash_password("pw").salt != made.salt  # a new salt each time


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ("plain", "is not a scrypt$N$r$p$salt$key line"),
        ("bcrypt$16384$8$1$AAAAAAAAAAA$AAAAAAAAAAAAAAAAAAAAAA", "is not a scrypt"),
        ("scrypt$x$8$1$AAAAAAAAAAA$AAAAAAAAAAAAAAAAAAAAAA", "its N, r and p are not numbers"),
        ("scrypt$1024$8$1$AAAAAAAAAAA$AAAAAAAAAAAAAAAAAAAAAA", "its N (1024) is not a power"),
        ("scrypt$20000$8$1$AAAAAAAAAAA$AAAAAAAAAAAAAAAAAAAAAA", "its N (20000) is not a power"),
        ("scrypt$16384$99$1$AAAAAAAAAAA$AAAAAAAAAAAAAAAAAAAAAA", "its r (99) or p (1)"),
        ("scrypt$1048576$32$16$AAAAAAAAAAA$AAAAAAAAAAAAAAAAAAAAAA", "MiB per login"),
        ("scrypt$16384$8$1$AA*A$AAAAAAAAAAAAAAAAAAAAAA", "not base64"),
        ("scrypt$16384$8$1$AAAA$AAAAAAAAAAAAAAAAAAAAAA", "too short"),
    ],
)
def test_a_bad_line_is_refused_with_the_reason(line: str, reason: str) -> None:
    with pytest.raises(BadHash, match=None) as err:
        parse_hash(line)
    assert str(err.value).startswith(reason) or reason in str(err.value), str(err.value)


def test_tokens_are_random_and_kept_as_sha256() -> None:
    token = new_token()
    assert len(token) >= 43 and token != new_token()
    assert token_digest(token) == hashlib.sha256(token.encode()).hexdigest()
    assert token_digest(f" {token}\n") == token_digest(token)
    assert is_token_digest(token_digest(token)) and not is_token_digest(token)
