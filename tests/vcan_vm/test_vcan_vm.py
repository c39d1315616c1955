"""``make test-vcan``'s own logic, on the host: never a pass unless every vcan test ran and
passed in the VM; the kernel modules in the order their dependencies need."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path
from typing import Any

import pytest

from tests.vcan_vm import __main__ as vm

JUNIT = """<?xml version="1.0" encoding="utf-8"?><testsuites><testsuite name="pytest"
errors="{errors}" failures="{failures}" skipped="{skipped}" tests="{tests}" time="1.0"/>
</testsuites>"""


def report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, **counts: int) -> None:
    path = tmp_path / "junit.xml"
    values = {"errors": 0, "failures": 0, "skipped": 0, "tests": 3, **counts}
    path.write_text(JUNIT.format(**values))
    monkeypatch.setattr(vm, "JUNIT", path)


def test_a_clean_run_passes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    report(tmp_path, monkeypatch)
    assert vm.verdict(0, time.monotonic(), "VM", expected=3) == 0


@pytest.mark.parametrize(
    ("code", "counts", "expected"),
    [
        (0, {"skipped": 1}, 3),  # a skip is never counted as a pass
        (1, {"failures": 1}, 3),
        (0, {"tests": 0}, None),  # nothing ran
        (0, {"tests": 2}, 3),  # fewer ran than were collected
        (1, {}, 3),  # pytest said no, whatever the report says
    ],
)
def test_anything_less_fails(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    code: int,
    counts: dict[str, int],
    expected: int | None,
) -> None:
    report(tmp_path, monkeypatch, **counts)
    assert vm.verdict(code, time.monotonic(), "VM", expected) == 1


def test_no_report_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(vm, "JUNIT", tmp_path / "missing.xml")
    assert vm.verdict(0, time.monotonic(), "VM", 3) == 1


def test_a_vm_that_ran_nothing_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """qemu exits 0 but the guest never wrote its exit status (it did not boot, the 9p
    mount failed, Python did not start): a failure, never a pass."""
    monkeypatch.setattr(vm, "RUN", tmp_path / "run")
    monkeypatch.setattr(vm, "STATUS", tmp_path / "run" / "status.json")
    monkeypatch.setattr(vm, "ARGS", tmp_path / "run" / "args.json")
    monkeypatch.setattr(vm, "ensure_packages", lambda: None)
    monkeypatch.setattr(vm, "ensure_kernel", lambda: (tmp_path, "6.1.0-test"))
    monkeypatch.setattr(vm, "ensure_initrd", lambda tree, version: tmp_path / "initrd.gz")
    monkeypatch.setattr(vm, "speed_probe", lambda: 0.1)

    def qemu(cmd: list[str], **kw: Any) -> subprocess.CompletedProcess[bytes]:
        assert cmd[0] == "qemu-system-x86_64" and "-nic" in cmd and "tcg" in cmd
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(subprocess, "run", qemu)
    assert vm.run_in_vm(["tests/x.py::t"]) == 1


def test_modules_load_after_what_they_need(tmp_path: Path) -> None:
    base = tmp_path / "lib" / "modules" / "6.1.0-test"
    base.mkdir(parents=True)
    dep = {
        "kernel/drivers/net/can/vcan.ko": ["kernel/drivers/net/can/dev/can-dev.ko"],
        "kernel/drivers/net/can/dev/can-dev.ko": [],
        "kernel/net/can/can-raw.ko": ["kernel/net/can/can.ko"],
        "kernel/net/can/can.ko": [],
        "kernel/drivers/virtio/virtio_pci.ko": [
            "kernel/drivers/virtio/virtio_pci_modern_dev.ko",
            "kernel/drivers/virtio/virtio.ko",
            "kernel/drivers/virtio/virtio_ring.ko",
        ],
        "kernel/drivers/virtio/virtio_pci_modern_dev.ko": [],
        "kernel/drivers/virtio/virtio.ko": ["kernel/drivers/virtio/virtio_ring.ko"],
        "kernel/drivers/virtio/virtio_ring.ko": [],
        "kernel/net/9p/9pnet_virtio.ko": ["kernel/net/9p/9pnet.ko"],
        "kernel/net/9p/9pnet.ko": [],
        "kernel/fs/9p/9p.ko": ["kernel/net/9p/9pnet.ko"],
        "kernel/net/sched/sch_tbf.ko": [],
    }
    (base / "modules.dep").write_text(
        "".join(f"{path}: {' '.join(needs)}\n" for path, needs in dep.items())
    )
    order = [vm.module_name(p.name) for p in vm.module_order(tmp_path, "6.1.0-test")]
    for module, needs in dep.items():
        for need in needs:
            assert order.index(vm.module_name(need)) < order.index(vm.module_name(module))
    assert order.index("virtio_ring") < order.index("virtio") and "can_dev" in order


def test_the_guest_keeps_the_hosts_tmp_when_the_project_lives_there() -> None:
    """A CI clone under /tmp: the guest must not hide it under a tmpfs of its own."""
    guards = [line for line in vm.INIT.splitlines() if line.strip().startswith('case "$root/"')]
    assert len(guards) == 2
    script = "\n".join(line.replace("mount -t tmpfs tmpfs", "echo") for line in guards)
    for root, mounted in (
        ("/tmp/clone", ["/host/run"]),
        ("/srv/checkout", ["/host/tmp", "/host/run"]),
    ):
        run = subprocess.run(
            ["sh", "-c", f"root={root}\n{script}"], capture_output=True, text=True, check=True
        )
        assert run.stdout.split() == mounted
