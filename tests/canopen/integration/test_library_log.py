"""The canopen library's own log lines held at ``gateway.library_log_level`` (WARNING): a
reconnect of a CiA 402 drive logs a bounded number of lines, the gateway's own."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

from gateway.cli.run import LIBRARY_LOGGERS, set_library_level
from gateway.model import CommState
from tests.canopen.integration.conftest import drive, rig

RECONNECT_LINES = 20
"""Lines one reconnect may log at INFO (the gateway's: offline, the reason, online again;
the library alone logged about 100 at INFO)."""


class Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@pytest.fixture
def logged() -> Iterator[Lines]:
    """The root logger at INFO, as the daemon's set-up leaves it, with the libraries at
    their default level; every line that passes counted."""
    root = logging.getLogger()
    level = root.level
    lines = Lines()
    root.addHandler(lines)
    root.setLevel(logging.INFO)
    set_library_level("WARNING")
    try:
        yield lines
    finally:
        root.removeHandler(lines)
        root.setLevel(level)
        for name in LIBRARY_LOGGERS:
            logging.getLogger(name).setLevel(logging.NOTSET)


async def test_a_reconnect_logs_a_bounded_number_of_lines(logged: Lines) -> None:
    async with rig([drive(5)]) as r:
        await r.wait("d5", lambda s: s.comm is CommState.ONLINE)
        before = len(logged.records)
        r.sim.node(5).silence(True)
        await r.wait("d5", lambda s: s.comm is CommState.OFFLINE)
        r.sim.node(5).silence(False)
        await r.wait("d5", lambda s: s.comm is CommState.ONLINE)
        reconnect = logged.records[before:]
    library = [x for x in reconnect if x.name.split(".")[0] in LIBRARY_LOGGERS]
    assert [x.getMessage() for x in library if x.levelno < logging.WARNING] == []
    assert len(reconnect) <= RECONNECT_LINES, [x.getMessage() for x in reconnect]


def test_library_log_level_is_a_config_key_defaulting_to_warning() -> None:
    from gateway.config import parse

    assert parse({}, "t.toml").gateway.library_log_level == "WARNING"
    raised = parse({"gateway": {"library_log_level": "DEBUG"}}, "t.toml")
    assert raised.gateway.library_log_level == "DEBUG"
