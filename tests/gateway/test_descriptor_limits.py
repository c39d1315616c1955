"""The descriptor limit against the configured limits (gateway/runtime/limits.py), with
``getrlimit`` and ``setrlimit`` replaced: the process's own limit is never touched."""

from __future__ import annotations

import errno
import resource
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import pytest

from gateway.config import Config, load
from gateway.runtime.limits import (
    DESCRIPTORS_PER_BUS,
    FIXED_MARGIN,
    LISTENING_SOCKETS,
    SOFT_LIMIT_WANTED,
    WEB_CONNECTIONS_WITHOUT_A_LIMIT,
    DescriptorNeed,
    descriptor_need,
    descriptor_problems,
)

ROOT = Path(__file__).resolve().parents[2]
UNIT = ROOT / "config" / "drive-gateway.service"
LOG = "gateway.runtime.limits"


def site(tmp_path: Path, modbus: str = "", buses: int = 1) -> Config:
    text = f"[zenoh]\nenabled = false\n[modbus]\n{modbus}\n"
    for n in range(buses):
        text += f"[buses.line{n}]\nadapter = 'fake'\n"
    path = tmp_path / "site.toml"
    path.write_text(text)
    return load(path)


def with_web(config: Config, web: object) -> Config:
    """``config`` with a stand-in ``[web]`` (only what the check reads of it)."""
    return replace(config, web=cast(Any, web))


class Limits:
    """A stand-in for the process's RLIMIT_NOFILE: what getrlimit says, what was set."""

    def __init__(self, soft: int, hard: int, refuse: OSError | None = None) -> None:
        self.soft, self.hard, self.refuse = soft, hard, refuse
        self.set: list[tuple[int, int]] = []

    def getrlimit(self, which: int) -> tuple[int, int]:
        assert which == resource.RLIMIT_NOFILE
        return self.soft, self.hard

    def setrlimit(self, which: int, value: tuple[int, int]) -> None:
        assert which == resource.RLIMIT_NOFILE
        if self.refuse is not None:
            raise self.refuse
        self.set.append(value)
        self.soft, self.hard = value


@pytest.fixture
def rlimit(monkeypatch: pytest.MonkeyPatch) -> Any:
    def install(soft: int, hard: int, refuse: OSError | None = None) -> Limits:
        fake = Limits(soft, hard, refuse)
        monkeypatch.setattr(resource, "getrlimit", fake.getrlimit)
        monkeypatch.setattr(resource, "setrlimit", fake.setrlimit)
        return fake

    return install


# ---------------------------------------------------------------- the need


def test_the_need_adds_the_front_ends_limits_the_buses_and_a_margin(tmp_path: Path) -> None:
    config = site(tmp_path, "max_connections = 300", buses=2)
    assert not config.web.enabled
    need = descriptor_need(config)
    assert need == DescriptorNeed(
        modbus=300 + LISTENING_SOCKETS, web=0, buses=2 * DESCRIPTORS_PER_BUS
    )
    assert need.total == 300 + LISTENING_SOCKETS + 2 * DESCRIPTORS_PER_BUS + FIXED_MARGIN
    off = site(tmp_path, "enabled = false", buses=0)
    assert descriptor_need(off).total == FIXED_MARGIN


def test_the_web_limit_is_read_where_the_config_has_one(tmp_path: Path) -> None:
    config = site(tmp_path)
    limited = with_web(
        config, SimpleNamespace(enabled=True, limits=SimpleNamespace(max_connections=700))
    )
    assert descriptor_need(limited).web == 700 + LISTENING_SOCKETS
    unlimited = with_web(config, SimpleNamespace(enabled=True))
    assert descriptor_need(unlimited).web == WEB_CONNECTIONS_WITHOUT_A_LIMIT + LISTENING_SOCKETS
    assert descriptor_need(with_web(config, SimpleNamespace(enabled=False))).web == 0


# ---------------------------------------------------------------- the check


def test_a_limit_that_covers_the_config_is_left_alone(tmp_path: Path, rlimit: Any) -> None:
    fake = rlimit(1024, 1024)
    assert descriptor_problems(site(tmp_path)) == []  # 100 + 2 + 8 + 256 of 1024
    assert fake.set == []


def test_a_short_soft_limit_is_raised_towards_the_hard_one(
    tmp_path: Path, rlimit: Any, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level("INFO", LOG)
    fake = rlimit(1024, 524288)
    config = site(tmp_path, "max_connections = 1000")
    assert descriptor_problems(config) == []
    assert fake.set == [(SOFT_LIMIT_WANTED, 524288)]
    need = descriptor_need(config).total
    assert caplog.messages == [
        f"file descriptor limit raised from 1024 to {SOFT_LIMIT_WANTED}: the configured"
        f" limits may need {need}"
    ]


def test_the_soft_limit_is_raised_no_further_than_the_hard_one(tmp_path: Path, rlimit: Any) -> None:
    fake = rlimit(1024, 4096)
    assert descriptor_problems(site(tmp_path, "max_connections = 1000")) == []
    assert fake.set == [(4096, 4096)]
    infinite = rlimit(1024, resource.RLIM_INFINITY)
    assert descriptor_problems(site(tmp_path, "max_connections = 1000")) == []
    assert infinite.set == [(SOFT_LIMIT_WANTED, resource.RLIM_INFINITY)]


def test_a_short_hard_limit_is_a_problem_that_names_the_figures(
    tmp_path: Path, rlimit: Any
) -> None:
    fake = rlimit(256, 512)
    config = with_web(
        site(tmp_path, "max_connections = 200"),
        SimpleNamespace(enabled=True, limits=SimpleNamespace(max_connections=128)),
    )
    need = descriptor_need(config)
    assert need.total == 202 + 130 + 8 + FIXED_MARGIN
    assert descriptor_problems(config) == [
        f"the file descriptor limit (512, the hard limit) is below the {need.total}"
        " descriptors the configured limits may need (Modbus 202, web 130, buses 8,"
        f" Zenoh, the log and the event loop {FIXED_MARGIN}): once they are used up no"
        " front end accepts a connection; raise LimitNOFILE= in the unit (systemctl edit"
        " drive-gateway) or lower modbus.max_connections or web.max_connections"
    ]
    assert fake.set == [(512, 512)]  # as far as it goes


def test_a_refused_raise_is_a_problem(tmp_path: Path, rlimit: Any) -> None:
    rlimit(256, 4096, refuse=PermissionError(errno.EPERM, "Operation not permitted"))
    [problem] = descriptor_problems(site(tmp_path, "max_connections = 1000"))
    assert problem.startswith("the file descriptor limit (256) is below the ")
    assert "raising it failed: [Errno 1] Operation not permitted" in problem


# ---------------------------------------------------------------- the unit


def unit_setting(name: str) -> str:
    [value] = [
        line.split("=", 1)[1]
        for line in UNIT.read_text().splitlines()
        if line.startswith(f"{name}=")
    ]
    return value


def test_the_unit_covers_the_most_the_config_admits(tmp_path: Path) -> None:
    """modbus.max_connections and web.max_connections at their maximum (1000 each),
    sixteen buses: still within the unit's LimitNOFILE, soft and hard."""
    config = with_web(
        site(tmp_path, "max_connections = 1000", buses=16),
        SimpleNamespace(enabled=True, limits=SimpleNamespace(max_connections=1000)),
    )
    assert int(unit_setting("LimitNOFILE")) >= descriptor_need(config).total
