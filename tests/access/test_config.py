"""``[[users]]``, ``[audit]`` and ``[[modbus.peers]]`` in the config file; the CLI's lines."""

from __future__ import annotations

import ipaddress
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.access.passwords import hash_password, parse_hash, token_digest, verify_password
from gateway.access.roles import Role
from gateway.config import ModbusSection, load
from gateway.errors import ConfigErrors

HASH = hash_password("a good password", n=1 << 14).line()
DIGEST = token_digest("tok")


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "site.toml"
    path.write_text(text)
    return path


def errors_of(tmp_path: Path, text: str) -> list[str]:
    with pytest.raises(ConfigErrors) as err:
        load(write(tmp_path, text))
    return [f"{e.key}: {e.reason}" for e in err.value.errors]


def test_users_with_their_roles_and_hashes(tmp_path: Path) -> None:
    config = load(
        write(
            tmp_path,
            f'[[users]]\nname = "ana"\nrole = "operator"\npassword = "{HASH}"\n'
            f'[[users]]\nname = "scada-1"\nrole = "viewer"\ntoken_sha256 = "{DIGEST}"\n',
        )
    )
    ana, scada = config.users
    assert (ana.name, ana.role, ana.token_sha256) == ("ana", Role.OPERATOR, None)
    assert ana.password is not None and verify_password("a good password", ana.password)
    assert (scada.role, scada.password, scada.token_sha256) == (Role.VIEWER, None, DIGEST)


@pytest.mark.parametrize(
    ("users", "message"),
    [
        ('name = "a"\nrole = "root"\npassword = "x"', "users[0].role: 'root' is not a role"),
        ('name = "a b"\nrole = "admin"', "users[0].name: 'a b' is not a user name"),
        ('name = "a"\nrole = "admin"', "users[0].name: user 'a' has neither a password"),
        ('name = "a"\nrole = "admin"\npassword = "hunter2"', "users[0].password: is not a scrypt"),
        ('name = "a"\nrole = "admin"\ntoken_sha256 = "ab"', "users[0].token_sha256: must be"),
        (
            f'name = "a"\nrole = "admin"\npassword = "{HASH}"\nemail = "x"',
            "users[0].email: unknown",
        ),
    ],
)
def test_a_bad_user_is_named(tmp_path: Path, users: str, message: str) -> None:
    found = errors_of(tmp_path, f"[[users]]\n{users}\n")
    assert any(f.startswith(message) for f in found), found


def test_a_user_named_twice(tmp_path: Path) -> None:
    one = f'[[users]]\nname = "a"\nrole = "admin"\ntoken_sha256 = "{DIGEST}"\n'
    found = errors_of(tmp_path, one + one)
    assert "users: user 'a' is named twice" in found
    assert "users: two users have the same token_sha256" in found


def test_commands_for_other_machines_need_users(tmp_path: Path) -> None:
    web = '[web]\nbind = "0.0.0.0:8080"\nallow = ["10.0.0.0/8"]\ncommands = true\n'
    found = errors_of(tmp_path, web)
    assert found == [
        "web.commands: commands = true on a page other machines reach needs [[users]]: each "
        "person a name, a role and a password hash (drive-gateway users hash); or set "
        "commands = false"
    ]
    user = f'[[users]]\nname = "ana"\nrole = "operator"\npassword = "{HASH}"\n'
    assert load(write(tmp_path, web + user)).web.commands


def test_check_config_refuses_commands_without_users(tmp_path: Path) -> None:
    path = write(tmp_path, '[web]\nbind = "0.0.0.0:8080"\nallow = ["0.0.0.0/0"]\ncommands = true\n')
    done = subprocess.run(
        [sys.executable, "-m", "gateway", "check-config", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2
    assert "commands = true on a page other machines reach needs [[users]]" in done.stderr


def test_the_audit_table(tmp_path: Path) -> None:
    config = load(write(tmp_path, '[audit]\nfile = "audit/a.log"\nmax_kib = 64\nbackups = 3\n'))
    assert config.audit.file == tmp_path / "audit" / "a.log"
    assert (config.audit.max_kib, config.audit.backups, config.audit.journal) == (64, 3, True)
    assert errors_of(tmp_path, "[audit]\nmax_kib = 1\n") == [
        "audit.max_kib: 1 is below the minimum 16"
    ]
    assert errors_of(tmp_path, '[audit]\nfile = "a\\u0000b"\n') == [
        "audit.file: 'a\\x00b' is not a file path"
    ]


def test_modbus_peers_and_their_rights(tmp_path: Path) -> None:
    config = load(
        write(
            tmp_path,
            '[modbus]\n[[modbus.peers]]\naddress = "10.0.0.0/8"\nrights = "read"\n'
            '[[modbus.peers]]\naddress = "10.1.2.3"\nrights = "command"\n',
        )
    )
    section = config.modbus
    assert section.peers == (
        (ipaddress.ip_network("10.0.0.0/8"), False),
        (ipaddress.ip_network("10.1.2.3/32"), True),
    )
    assert not section.may_command("10.9.9.9")  # the /8: read
    assert section.may_command("10.1.2.3")  # its own /32: command
    assert section.may_command("::ffff:10.1.2.3")
    assert section.may_command("192.168.1.1")  # no entry: as before
    assert not ModbusSection(read_only=True).may_command("192.168.1.1")
    found = errors_of(tmp_path, '[[modbus.peers]]\naddress = "x"\nrights = "write"\n')
    assert found == ['modbus.peers[0].rights: \'write\' is not "read" or "command"']


def test_at_equal_length_read_wins() -> None:
    net = ipaddress.ip_network("10.0.0.0/8")
    assert not ModbusSection(peers=((net, True), (net, False))).may_command("10.0.0.1")


def test_the_cli_prints_the_lines_a_users_table_takes() -> None:
    def run(*args: str, stdin: str = "") -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "gateway", "users", *args],
            input=stdin,
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )

    done = run("hash", stdin="a good password\n")
    assert done.returncode == 0, done.stderr
    key, _, value = done.stdout.strip().partition(" = ")
    assert key == "password"
    assert verify_password("a good password", parse_hash(value.strip('"')))
    assert run("hash", stdin="short\n").returncode == 2
    done = run("token")
    token = done.stderr.rsplit(" ", 1)[-1].strip()
    assert done.stdout.strip() == f'token_sha256 = "{token_digest(token)}"'
