"""asyncua's own log lines held at ``gateway.library_log_level`` (WARNING) like the other
libraries': it logs every node of the standard address space it could not place at INFO
(about 1,100 lines at each start of the OPC UA server)."""

from __future__ import annotations

import logging
from pathlib import Path

from tests.canopen.integration.test_library_log import Lines, logged
from tests.opcua.harness import running_gateway

__all__ = ["logged"]  # the fixture, shared


async def test_a_server_start_logs_none_of_asyncuas_info_lines(
    tmp_path: Path, logged: Lines
) -> None:
    async with running_gateway(tmp_path):
        pass
    library = [x for x in logged.records if x.name.startswith("asyncua")]
    assert [x.getMessage() for x in library if x.levelno < logging.WARNING] == []
    assert len(logged.records) < 100
