"""``make install``: a production install of drive-gateway (standard library only).

Builds ``PREFIX/venv`` with the runtime dependencies only (no dev tools), on an interpreter
the unit's sandbox can read; installs the systemd unit with its paths filled in, the site
config (never over an existing one), the user, the shell completions and the man page;
then checks the unit (``systemd-analyze verify``, where the tool exists) and prints the
next steps, in the order docs/operations.md walks them.

Every path is a make variable (docs/operations.md lists them), so the tests install into a
temporary directory with ``CREATE_USER=no``.
"""

from __future__ import annotations

import argparse
import grp
import os
import pwd
import re
import shutil
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
UNIT_TEMPLATE = ROOT / "config" / "drive-gateway.service"
SITE_TEMPLATE = ROOT / "config" / "site.example.toml"
MIN_PYTHON = (3, 11)

# What the unit's sandbox hides (systemd.exec(5)); the unit's own settings decide which apply.
HIDDEN_BY = {
    "ProtectHome": ("/root", "/home", "/run/user"),
    "PrivateTmp": ("/tmp", "/var/tmp"),
}
SYSTEM_PYTHONS = tuple(
    f"{d}/python3{v}"
    for d in ("/usr/bin", "/usr/local/bin")
    for v in (".14", ".13", ".12", ".11", "")
)

# The unit template's paths, replaced by the install's.
TEMPLATE_PREFIX = "/opt/drive-gateway"
TEMPLATE_SYSCONF = "/etc/drive-gateway"


class InstallError(Exception):
    """The install cannot go on; the text says why and what to do."""


@dataclass(frozen=True)
class Options:
    prefix: Path
    sysconfdir: Path
    unitdir: Path
    bindir: Path
    bashcompdir: Path
    zshcompdir: Path
    mandir: Path
    python: str
    user: str
    create_user: bool
    wheel: Path | None


def say(text: str) -> None:
    print(text, flush=True)


# ---------------------------------------------------------------- the interpreter


def unit_settings(text: str) -> dict[str, str]:
    return {
        line.split("=", 1)[0]: line.split("=", 1)[1]
        for line in text.splitlines()
        if "=" in line and not line.lstrip().startswith("#")
    }


def hidden_roots(unit_text: str) -> dict[str, str]:
    """Directory -> the unit setting that hides it from the service."""
    settings = unit_settings(unit_text)
    out = {}
    for setting, roots in HIDDEN_BY.items():
        value = settings.get(setting, "no")
        if value in ("yes", "true", "tmpfs"):  # ProtectHome=read-only still lets it read
            out.update({root: f"{setting}={value}" for root in roots})
    return out


def hidden_by(path: str, roots: dict[str, str]) -> str | None:
    """The setting that hides ``path`` from the service, or None."""
    real = os.path.realpath(path)
    for root, setting in roots.items():
        if real == root or real.startswith(root + "/"):
            return setting
    return None


def probe(python: str) -> tuple[tuple[int, int], list[str]] | None:
    """(version, [executable, base prefix] as it resolves them), or None when it does not run
    or cannot make a venv with pip (Debian's python3-venv missing)."""
    code = (
        "import sys, os, venv, ensurepip;"
        "print(sys.version_info[0], sys.version_info[1]);"
        "print(os.path.realpath(sys.executable)); print(os.path.realpath(sys.base_prefix))"
    )
    try:
        out = subprocess.run(
            [python, "-c", code], capture_output=True, text=True, timeout=60, check=True
        ).stdout.split("\n")
    except (OSError, subprocess.SubprocessError):
        return None
    major, minor = (int(x) for x in out[0].split())
    return (major, minor), [out[1], out[2]]


def choose_python(asked: str, roots: dict[str, str]) -> str:
    """``asked`` when the service can read it, else a system interpreter; InstallError with
    what to do when there is none."""
    problem = _unusable(asked, roots)
    if problem is None:
        return asked
    say(f"  {asked}: {problem}")
    for candidate in SYSTEM_PYTHONS:
        if os.path.exists(candidate) and _unusable(candidate, roots) is None:
            say(f"  using {candidate} instead (the unit's sandbox can read it)")
            return candidate
    raise InstallError(
        f"{asked} cannot run the service ({problem}) and no system Python "
        f"{MIN_PYTHON[0]}.{MIN_PYTHON[1]}+ with venv was found in /usr/bin or /usr/local/bin. "
        "Install one (Debian/Ubuntu: apt install python3 python3-venv; it must be 3.11 or "
        "newer) and run `make install PYTHON=/usr/bin/python3.11 ...`, or build Python under "
        "/opt or /usr/local. Relaxing ProtectHome= in the unit is not advised."
    )


def _unusable(python: str, roots: dict[str, str]) -> str | None:
    found = probe(python)
    if found is None:
        return "does not run, or has no venv/ensurepip module"
    version, paths = found
    if version < MIN_PYTHON:
        return f"is Python {version[0]}.{version[1]}; drive-gateway needs 3.11 or newer"
    for path in paths:
        setting = hidden_by(path, roots)
        if setting is not None:
            return f"lives in {path}, which the unit's {setting} hides from the service"
    return None


# ---------------------------------------------------------------- the steps


def run(argv: list[str]) -> None:
    say("  $ " + " ".join(argv))
    subprocess.run(argv, check=True)


def build_venv(opts: Options, python: str) -> Path:
    venv = opts.prefix / "venv"
    opts.prefix.mkdir(parents=True, exist_ok=True)
    run([python, "-m", "venv", "--clear", str(venv)])
    pip = [str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet"]
    run([*pip, str(opts.wheel) if opts.wheel else str(ROOT)])  # no [dev]: runtime only
    return venv


def ensure_user(opts: Options) -> None:
    try:
        pwd.getpwnam(opts.user)
        say(f"  user {opts.user} exists")
        return
    except KeyError:
        pass
    if not opts.create_user:
        say(f"  user {opts.user} not created (CREATE_USER=no): create it before starting")
        return
    groups = ["--groups", "dialout"] if _group_exists("dialout") else []
    run(
        [
            "useradd",
            "--system",
            "--home-dir",
            "/var/lib/drive-gateway",
            "--no-create-home",
            "--shell",
            "/usr/sbin/nologin",
            *groups,
            opts.user,
        ]
    )


def _group_exists(name: str) -> bool:
    try:
        grp.getgrnam(name)
    except KeyError:
        return False
    return True


def install_config(opts: Options, venv: Path) -> Path:
    opts.sysconfdir.mkdir(parents=True, exist_ok=True)
    group = opts.user if _group_exists(opts.user) else None
    _own(opts.sysconfdir, group, 0o750)
    site = opts.sysconfdir / "site.toml"
    if site.exists():
        say(f"  {site} exists: kept (the template is {SITE_TEMPLATE.name} in {venv_share(venv)})")
    else:
        shutil.copyfile(SITE_TEMPLATE, site)
        _own(site, group, 0o640)
        say(f"  {site} written from {SITE_TEMPLATE.name}: fill it in (next steps)")
    return site


def venv_share(venv: Path) -> Path:
    return venv / "share" / "drive-gateway"


def _own(path: Path, group: str | None, mode: int) -> None:
    path.chmod(mode)
    if group is not None and os.geteuid() == 0:
        shutil.chown(path, "root", group)


def unit_text(opts: Options, venv: Path) -> str:
    text = UNIT_TEMPLATE.read_text()
    text = text.replace(f"{TEMPLATE_PREFIX}/venv", str(venv))
    text = text.replace(f"{TEMPLATE_PREFIX}/doc", str(opts.prefix / "doc"))
    text = text.replace(TEMPLATE_SYSCONF, str(opts.sysconfdir))
    if opts.user != "drive-gateway":
        text = re.sub(r"^(User|Group)=drive-gateway$", rf"\1={opts.user}", text, flags=re.M)
    return text


def install_unit(opts: Options, venv: Path) -> Path:
    opts.unitdir.mkdir(parents=True, exist_ok=True)
    unit = opts.unitdir / "drive-gateway.service"
    unit.write_text(unit_text(opts, venv))
    unit.chmod(0o644)
    return unit


def install_docs(opts: Options) -> None:
    doc = opts.prefix / "doc"
    doc.mkdir(parents=True, exist_ok=True)
    for source in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        if source.is_file():
            shutil.copyfile(source, doc / source.name)


def install_tools(opts: Options, venv: Path) -> None:
    exe = venv / "bin" / "drive-gateway"
    opts.bindir.mkdir(parents=True, exist_ok=True)
    link = opts.bindir / "drive-gateway"
    if link.is_symlink() or link.exists():
        link.unlink()
    link.symlink_to(exe)
    outputs = {
        opts.bashcompdir / "drive-gateway": ["completion", "bash"],
        opts.zshcompdir / "_drive-gateway": ["completion", "zsh"],
        opts.mandir / "man1" / "drive-gateway.1": ["manpage"],
    }
    for target, args in outputs.items():
        target.parent.mkdir(parents=True, exist_ok=True)
        text = subprocess.run(
            [str(exe), *args], capture_output=True, text=True, check=True, timeout=120
        ).stdout
        target.write_text(text)
        target.chmod(0o644)
        say(f"  {target}")


def modbus_agreement(site: Path, unit: Path) -> str | None:
    """Why the site config's Modbus port and the unit's capabilities disagree, or None."""
    try:
        config = tomllib.loads(site.read_text())
    except (OSError, tomllib.TOMLDecodeError):
        return None  # check-config says what is wrong with it
    modbus = config.get("modbus", {})
    if not isinstance(modbus, dict) or modbus.get("enabled", True) is False:
        return None
    bind = str(modbus.get("bind", "0.0.0.0:502"))
    try:
        port = int(bind.rsplit(":", 1)[1])
    except (IndexError, ValueError):
        return None
    caps = unit_settings(unit.read_text()).get("AmbientCapabilities", "")
    if port < 1024 and "CAP_NET_BIND_SERVICE" not in caps:
        return (
            f"{site} binds Modbus port {port}, but {unit} grants no CAP_NET_BIND_SERVICE: "
            "the gateway would exit 2 at start"
        )
    return None


def verify_unit(unit: Path) -> None:
    tool = shutil.which("systemd-analyze")
    if tool is None:
        say("  systemd-analyze not found: unit not verified")
        return
    proc = subprocess.run([tool, "verify", str(unit)], capture_output=True, text=True, check=False)
    problems = [line for line in (proc.stdout + proc.stderr).splitlines() if unit.name in line]
    if problems:
        say("  systemd-analyze verify:\n" + "\n".join(f"    {p}" for p in problems))
    else:
        say(f"  systemd-analyze verify {unit}: ok")


def next_steps(opts: Options, site: Path, unit: Path) -> list[str]:
    exe = opts.bindir / "drive-gateway"
    return [
        f"Fill in the site config: sudoedit {site}  (buses, drives, Zenoh prefix, Modbus "
        "allow-list; every key is explained in it)",
        f"Check it until it says ok: {exe} check-config {site}",
        "Bring up the buses: the RS-485 converter's stable name (/dev/serial/by-id/...) in "
        "the config; for DeviceNet `ip link set can0 type can bitrate 125000 && ip link set "
        "can0 up` (docs/operations.md)",
        f"Start it at boot: systemctl daemon-reload && systemctl enable --now {unit.name}",
        f"Watch it start: systemctl status {unit.name}; journalctl -u {unit.stem} -f",
        f"Check every drive: {exe} watch --once --prefix <zenoh.prefix>  (exit 0: all online)",
        f"Back up each drive's parameters: {exe} params backup <drive> --prefix <zenoh.prefix>",
    ]


# ---------------------------------------------------------------- main


def parse(argv: list[str]) -> Options:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--prefix", type=Path, required=True)
    p.add_argument("--sysconfdir", type=Path, default=Path("/etc/drive-gateway"))
    p.add_argument("--unitdir", type=Path, default=Path("/etc/systemd/system"))
    p.add_argument("--bindir", type=Path, default=Path("/usr/local/bin"))
    p.add_argument(
        "--bashcompdir", type=Path, default=Path("/usr/local/share/bash-completion/completions")
    )
    p.add_argument("--zshcompdir", type=Path, default=Path("/usr/local/share/zsh/site-functions"))
    p.add_argument("--mandir", type=Path, default=Path("/usr/local/share/man"))
    p.add_argument("--python", default=sys.executable)
    p.add_argument("--user", default="drive-gateway")
    p.add_argument("--create-user", choices=("yes", "no"), default="yes")
    p.add_argument("--wheel", type=Path, help="install this wheel instead of the source tree")
    a = p.parse_args(argv)
    return Options(
        prefix=a.prefix.absolute(),
        sysconfdir=a.sysconfdir.absolute(),
        unitdir=a.unitdir.absolute(),
        bindir=a.bindir.absolute(),
        bashcompdir=a.bashcompdir.absolute(),
        zshcompdir=a.zshcompdir.absolute(),
        mandir=a.mandir.absolute(),
        python=a.python,
        user=a.user,
        create_user=a.create_user == "yes",
        wheel=a.wheel.absolute() if a.wheel else None,
    )


def install(opts: Options) -> int:
    roots = hidden_roots(UNIT_TEMPLATE.read_text())
    say("1. The interpreter (it must be readable inside the unit's sandbox)")
    python = choose_python(opts.python, roots)
    setting = hidden_by(str(opts.prefix), roots)
    if setting is not None:
        say(
            f"  warning: {opts.prefix} is hidden by the unit's {setting}: the service "
            "cannot start from there (a test install?)"
        )
    say(f"2. {opts.prefix}/venv with the runtime dependencies only")
    venv = build_venv(opts, python)
    say(f"3. The user {opts.user}")
    ensure_user(opts)
    say(f"4. The config directory {opts.sysconfdir}")
    site = install_config(opts, venv)
    say(f"5. The unit {opts.unitdir}/drive-gateway.service")
    unit = install_unit(opts, venv)
    install_docs(opts)
    verify_unit(unit)
    disagreement = modbus_agreement(site, unit)
    if disagreement is not None:
        say(f"  warning: {disagreement}")
    say("6. The command, shell completions and man page")
    install_tools(opts, venv)
    say("")
    say('Installed. Next steps (docs/operations.md, "Installing on an edge box"):')
    for n, step in enumerate(next_steps(opts, site, unit), start=1):
        say(f"  {n}. {step}")
    return 0


def main(argv: list[str] | None = None) -> int:
    opts = parse(sys.argv[1:] if argv is None else argv)
    try:
        return install(opts)
    except InstallError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except subprocess.CalledProcessError as exc:
        print(
            f"error: {' '.join(map(str, exc.cmd))} failed (exit {exc.returncode})", file=sys.stderr
        )
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
