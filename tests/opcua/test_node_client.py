"""The OPC UA server as a client of another stack sees it: node-opcua's client
(tests/opcua_client/client.js), run by Node.js as a process of its own against a real
daemon: browse, read, subscribe, Run and Stop with a refusal, HistoryRead, and a fault
alarm acknowledged. Skipped, with the reason, when node or node-opcua is not installed
(`make test-opcua` installs node-opcua from npm into tests/opcua_client/)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import shutil
from pathlib import Path
from typing import Any

import pytest

from gateway.model import DriveStatus
from gateway.opcua.variables import RPM
from tests.opcua.harness import TIMEOUT, running_gateway

CLIENT_DIR = Path(__file__).resolve().parents[1] / "opcua_client"
NODE = shutil.which("node")
REQUIRED = os.environ.get("DRIVE_GATEWAY_OPCUA_NODE") == "required"
"""Set by `make test-opcua`: there a missing node or node-opcua fails instead of skipping."""


def _missing() -> str | None:
    if NODE is None:
        return "Node.js (node) is not installed"
    if not (CLIENT_DIR / "node_modules" / "node-opcua-client").is_dir():
        return "node-opcua is not installed: run `make test-opcua`"
    return None


@pytest.fixture(autouse=True)
def _node_opcua() -> None:
    missing = _missing()
    if missing is not None:
        if REQUIRED:
            pytest.fail(missing)
        pytest.skip(missing)


class NodeClient:
    """The node process: its JSON lines by step, and a line to its stdin."""

    def __init__(self, proc: asyncio.subprocess.Process) -> None:
        self.proc = proc
        self.steps: dict[str, dict[str, Any]] = {}

    async def until(self, step: str) -> dict[str, Any]:
        assert self.proc.stdout is not None
        async with asyncio.timeout(TIMEOUT * 2):
            while step not in self.steps:
                line = await self.proc.stdout.readline()
                if not line:
                    stderr = b"" if self.proc.stderr is None else await self.proc.stderr.read()
                    raise AssertionError(f"node client ended before {step}: {stderr[-2000:]!r}")
                text = line.decode().strip()
                if not text.startswith("{"):
                    continue  # node-opcua's own log lines
                data = json.loads(text)
                assert data["step"] != "error", data["message"]
                self.steps[data["step"]] = data
        return self.steps[step]

    def tell(self, line: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(line.encode() + b"\n")


async def test_node_opcua_client_browses_reads_subscribes_commands_and_acknowledges(
    tmp_path: Path,
) -> None:
    assert NODE is not None
    async with running_gateway(tmp_path) as gw:
        env = {
            **os.environ,
            "HOME": str(tmp_path),  # node-opcua keeps its client PKI under HOME
            "CLIENT_TIMEOUT_MS": str(int(TIMEOUT * 1000)),
        }
        proc = await asyncio.create_subprocess_exec(
            NODE,
            "client.js",
            gw.endpoint,
            cwd=CLIENT_DIR,
            env=env,
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        client = NodeClient(proc)
        try:
            browsed = await client.until("browsed")
            assert browsed["drives"] == ["m1", "m2", "soft"]
            assert {"SpeedRpm", "Run", "Stop", "FaultAlarm", "Firmware"} <= set(browsed["m1"])
            read = await client.until("read")
            assert read == {"step": "read", "device": "test", "unitId": RPM.unit_id, "unit": "rpm"}
            commands = await client.until("commands")
            assert commands["speed"] == {"status": "Good", "text": "accepted"}
            assert commands["run"] == {"status": "Good", "text": "accepted"}
            assert commands["refused"] == {
                "status": "BadInvalidState",
                "text": "drive m2 takes commands from modbus only",
            }
            assert commands["stop"] == {"status": "Good", "text": "accepted"}
            history = await client.until("history")
            assert history["values"] == [10.0 * i for i in range(10, 20)]
            event_history = await client.until("event_history")
            assert event_history["status"] == "Good"
            assert event_history["events"] == [
                {"source": "m1", "message": f"m1: m1 {i}", "severity": 800 if i == 10 else 200}
                for i in range(10, 16)  # the end time is within the range
            ]
            await client.until("waiting_alarm")
            line = gw.daemon.runtime.adapters["line1"]
            adapter: Any = line.adapter
            await line.call(lambda: adapter.inject_fault("m1", 9))
            await gw.wait_for("m1", lambda s: s.status is DriveStatus.FAULTED)
            client.tell("fault")
            alarm = await client.until("alarm")
            assert alarm["message"] == "m1: fault 9: test fault 9"
            assert (alarm["severity"], alarm["source"]) == (800, "m1")
            assert alarm["refusedRun"]["status"] == "BadInvalidState"
            assert "reset the fault" in alarm["refusedRun"]["text"]
            assert alarm["ack"] == "Good"
            assert alarm["again"] == "BadEventIdUnknown"  # its EventId is no longer the newest
            await client.until("done")
            async with asyncio.timeout(TIMEOUT):
                assert await proc.wait() == 0
        finally:
            if proc.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
                await proc.wait()
