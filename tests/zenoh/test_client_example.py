"""docs/zenoh-keys.md's client section: the Zenoh release it names is the one
pyproject.toml pins, and its Python client runs as printed against a gateway, which tells
it apart from the anonymous client by its source info."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from gateway.zenoh.keys import ZENOH_SERIES, client_example, render_markdown
from tests.support.timing import scaled
from tests.zenoh.client import Client
from tests.zenoh.conftest import PREFIX, GatewayProcess

ROOT = Path(__file__).resolve().parents[2]


def test_the_zenoh_release_named_is_the_one_pinned() -> None:
    pyproject = (ROOT / "pyproject.toml").read_text()
    pin = re.search(r'"eclipse-zenoh>=([0-9.]+),<([0-9.]+)"', pyproject)
    assert pin is not None and pin.group(1) == ZENOH_SERIES
    assert f'pip install "eclipse-zenoh>={pin.group(1)},<{pin.group(2)}"' in client_example()
    doc = render_markdown()
    assert f"built with Zenoh {ZENOH_SERIES}" in doc
    assert "**Every client sends its source info**" in doc and "`anonymous` client" in doc
    assert "```python\n" + client_example() in doc


def test_the_client_example_runs_and_is_told_apart(gateway: GatewayProcess) -> None:
    code = (
        client_example()
        .replace('"tcp/127.0.0.1:7447"', f'"{gateway.endpoint}"')
        .replace('PREFIX = "demo"', f'PREFIX = "{PREFIX}"')
        .replace('DRIVE = "cfw11"', 'DRIVE = "d2"')
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=scaled(60),
        check=False,
    )
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("state {") and "'id': 'd2'" in lines[0]
    assert lines[1] == "command {'accepted': True}"
    assert lines[2].startswith("P100 {") and "'number': 100" in lines[2]
    client = Client(gateway.endpoint)
    try:
        (reply,) = client.query(f"{PREFIX}/drives/d2/state", timeout=scaled(10))
        state = reply.json()
    finally:
        client.close()
    assert state["control_source"] == "zenoh"
    assert state["control_client"] and "anonymous" not in state["control_client"]
