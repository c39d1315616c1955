"""``python -m tests.vcan_vm``: run the ``vcan`` tests where SocketCAN exists (``make test-vcan``).

By default: on this kernel when it has AF_CAN and we are root (vcan0 made if
          missing); otherwise in a qemu VM (TCG) booting Debian's kernel package with its
          own can/can-raw/can-dev/vcan modules, the host's filesystem shared over 9p so the
          same .venv runs inside. The packages come from Debian (apt-get); the kernel is
          unpacked into .vcan-vm/ (never installed into /boot) and the initramfs is cached.
``--guest``: what runs inside the VM: makes vcan0, runs pytest, writes its exit status.

Never a false pass: the host reads the exit status and pytest's JUnit report that the guest
wrote into .vcan-vm/run/ (both removed before the boot) and fails when either is missing,
when anything failed, when nothing ran, or when any test was skipped.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import lzma
import math
import os
import shutil
import socket
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CACHE = ROOT / ".vcan-vm"
RUN = CACHE / "run"
STATUS = RUN / "status.json"
ARGS = RUN / "args.json"  # extra pytest arguments for the guest (a narrower selection)
JUNIT = RUN / "junit.xml"
CHANNEL = "vcan0"
# Python under TCG runs several times slower than on the host, and more on a loaded host:
# the guest times a small probe against the host's figure and the tests' waits and rig
# timers scale by the ratio, never by less than VM_TIME_SCALE (tests/support/timing.py).
VM_TIME_SCALE = 4.0
VM_TIME_SCALE_MAX = 40.0
VM_TIMEOUT = 1800.0  # s: the whole VM run, boot to power-off
PACKAGES = ("qemu-system-x86", "busybox-static", "cpio", "kmod")
TOOLS = {"qemu-system-x86_64": "qemu-system-x86", "cpio": "cpio", "depmod": "kmod"}
BUSYBOX = Path("/bin/busybox")
KERNEL_META = "linux-image-amd64"
# What the guest needs; modules.dep adds what they need (virtio, netfs, can, can-dev...).
MODULES = ("virtio_pci", "9pnet_virtio", "9p", "can_raw", "vcan", "sch_tbf")
GUEST_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"

INIT = """#!/bin/busybox sh
/bin/busybox mkdir -p /proc /sys /dev /host /sbin /usr/bin /usr/sbin
/bin/busybox --install -s
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
for m in $(cat /modules/order); do
    insmod /modules/$m.ko || echo "vcan-vm: insmod $m failed"
done
root=$(sed -n 's/.* vcanroot=\\([^ ]*\\).*/\\1/p' /proc/cmdline)
if mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000,cache=loose host /host; then
    mount -t proc proc /host/proc
    mount -t sysfs sysfs /host/sys
    mount -t devtmpfs devtmpfs /host/dev
    mkdir -p /host/dev/pts /host/dev/shm
    mount -t devpts devpts /host/dev/pts
    mount -t tmpfs tmpfs /host/dev/shm
    # the guest's own /tmp and /run, unless the project itself lives there (a CI clone)
    case "$root/" in /tmp/*) ;; *) mount -t tmpfs tmpfs /host/tmp ;; esac
    case "$root/" in /run/*) ;; *) mount -t tmpfs tmpfs /host/run ;; esac
    chroot /host /usr/bin/env -i -C "$root" PATH=%(path)s HOME=/root \\
        "$root/.venv/bin/python" -m tests.vcan_vm --guest
    sync
else
    echo "vcan-vm: cannot mount the host over 9p"
fi
poweroff -f
"""


class VmError(Exception):
    """The VM could not be prepared or booted; the text says what to do."""


@dataclass(frozen=True)
class Counts:
    tests: int
    failed: int
    errors: int
    skipped: int

    @property
    def passed(self) -> int:
        return self.tests - self.failed - self.errors - self.skipped

    def text(self) -> str:
        return (
            f"{self.passed} passed, {self.failed} failed, {self.errors} errors, "
            f"{self.skipped} skipped"
        )


def log(text: str) -> None:
    print(f"vcan-vm: {text}", flush=True)


# ---------------------------------------------------------------- the host's own kernel


def host_problem() -> str | None:
    """Why the vcan tests cannot run on this kernel, or None when they can (vcan0 made)."""
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no socket.AF_CAN"
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError as exc:
        return f"the kernel has no AF_CAN ({exc.strerror})"
    if os.geteuid() != 0:
        return "not root (the vcan tests take vcan0 down and up and set its queue)"
    if not Path(f"/sys/class/net/{CHANNEL}").exists():
        commands = (
            ["modprobe", "vcan"],
            ["ip", "link", "add", "dev", CHANNEL, "type", "vcan"],
        )
        for cmd in commands:
            if subprocess.run(cmd, check=False).returncode != 0:
                return f"cannot make {CHANNEL} ({' '.join(cmd)} failed)"
    if subprocess.run(["ip", "link", "set", "up", CHANNEL], check=False).returncode != 0:
        return f"cannot set {CHANNEL} up"
    return None


def pytest_command(junit: Path, extra: list[str]) -> list[str]:
    return [
        str(ROOT / ".venv" / "bin" / "python"),
        "-m",
        "pytest",
        "-m",
        "vcan",
        "-q",
        "-p",
        "no:cacheprovider",
        f"--junitxml={junit}",
        *extra,
    ]


def collect() -> list[str]:
    """The ``vcan`` tests' node ids, collected here (the guest collects only what runs)."""
    cmd = [*pytest_command(JUNIT, [])[:8], "--collect-only"]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    ids = [line for line in done.stdout.splitlines() if "::" in line]
    if done.returncode != 0 or not ids:
        raise VmError(f"collecting the vcan tests failed:\n{done.stdout}{done.stderr}")
    return ids


def run_on_host(extra: list[str]) -> int:
    RUN.mkdir(parents=True, exist_ok=True)
    JUNIT.unlink(missing_ok=True)
    started = time.monotonic()
    code = subprocess.run(pytest_command(JUNIT, extra), cwd=ROOT, check=False).returncode
    return verdict(code, started, "host")


# ---------------------------------------------------------------- preparing the VM


def ensure_packages() -> None:
    missing = sorted({pkg for tool, pkg in TOOLS.items() if shutil.which(tool) is None})
    if not is_static(BUSYBOX):
        missing.append("busybox-static")
    if not missing:
        return
    install = ["apt-get", "install", "-y", "--no-install-recommends", *PACKAGES]
    if os.geteuid() != 0:
        raise VmError(f"missing {', '.join(missing)}: run as root: {' '.join(install)}")
    log(f"installing {' '.join(PACKAGES)}")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    if subprocess.run(install, env=env, check=False).returncode != 0:
        subprocess.run(["apt-get", "update"], env=env, check=False)
        if subprocess.run(install, env=env, check=False).returncode != 0:
            raise VmError(f"{' '.join(install)} failed")


def is_static(path: Path) -> bool:
    """An ELF file without a program interpreter (PT_INTERP): runs without a libc."""
    try:
        data = path.read_bytes()
    except OSError:
        return False
    if data[:4] != b"\x7fELF" or data[4] != 2:  # 64-bit only
        return False
    phoff = int.from_bytes(data[0x20:0x28], "little")
    entsize = int.from_bytes(data[0x36:0x38], "little")
    count = int.from_bytes(data[0x38:0x3A], "little")
    for i in range(count):
        start = phoff + i * entsize
        if int.from_bytes(data[start : start + 4], "little") == 3:  # PT_INTERP
            return False
    return True


def output(cmd: list[str], cwd: Path | None = None) -> str:
    done = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise VmError(f"{' '.join(cmd)} failed: {done.stderr.strip()}")
    return done.stdout


def kernel_package() -> str:
    """The package linux-image-amd64 depends on (linux-image-<version>-amd64)."""
    for line in output(["apt-cache", "depends", KERNEL_META]).splitlines():
        kind, _, name = line.strip().partition(": ")
        if kind == "Depends" and name.startswith("linux-image-"):
            return name
    raise VmError(f"apt-cache depends {KERNEL_META} names no kernel package")


def ensure_kernel() -> tuple[Path, str]:
    """The unpacked kernel package: (its folder, the kernel version); cached."""
    package = kernel_package()
    tree = CACHE / package
    done = tree / ".unpacked"
    if not done.exists():
        shutil.rmtree(tree, ignore_errors=True)
        download = CACHE / "download"
        shutil.rmtree(download, ignore_errors=True)
        download.mkdir(parents=True)
        log(f"fetching {package} (apt-get download; nothing is installed)")
        output(["apt-get", "download", package], cwd=download)
        debs = sorted(download.glob("*.deb"))
        if len(debs) != 1:
            raise VmError(f"apt-get download {package} gave {len(debs)} files")
        output(["dpkg-deb", "-x", str(debs[0]), str(tree)])
        shutil.rmtree(download)
        versions = [p.name for p in (tree / "lib" / "modules").iterdir()]
        if len(versions) != 1:
            raise VmError(f"{package} holds modules for {versions}")
        output(["depmod", "-b", str(tree), versions[0]])
        done.write_text(versions[0])
    return tree, done.read_text().strip()


def module_order(tree: Path, version: str) -> list[Path]:
    """MODULES and everything they need, each after what it needs (from modules.dep)."""
    base = tree / "lib" / "modules" / version
    deps: dict[str, list[str]] = {}
    for line in (base / "modules.dep").read_text().splitlines():
        path, _, needs = line.partition(":")
        deps[path] = needs.split()
    by_name = {module_name(path): path for path in deps}
    order: list[str] = []

    def visit(path: str) -> None:
        if path in order:
            return
        for need in reversed(deps[path]):  # modules.dep lists the deepest dependency last
            visit(need)
        order.append(path)

    for name in MODULES:
        found = by_name.get(name)
        if found is None:
            raise VmError(f"kernel {version} has no module {name}")
        visit(found)
    return [base / path for path in order]


def module_name(path: str) -> str:
    name = path.rsplit("/", 1)[-1].split(".ko", 1)[0]
    return name.replace("-", "_")


def module_bytes(path: Path) -> bytes:
    data = path.read_bytes()
    if path.name.endswith(".ko.xz"):
        return lzma.decompress(data)
    if not path.name.endswith(".ko"):
        raise VmError(f"cannot unpack module {path.name} (plain or .xz only)")
    return data


def ensure_initrd(tree: Path, version: str) -> Path:
    """busybox + the modules + /init, as a gzip'd newc cpio; rebuilt when any input changes."""
    modules = module_order(tree, version)
    init = INIT % {"path": GUEST_PATH}
    key = hashlib.sha256(init.encode())
    key.update(BUSYBOX.read_bytes())
    for path in modules:
        key.update(path.name.encode())
    initrd = CACHE / f"initrd-{version}-{key.hexdigest()[:12]}.gz"
    if initrd.exists():
        return initrd
    for old in CACHE.glob("initrd-*.gz"):
        old.unlink()
    stage = CACHE / "initrd-stage"
    shutil.rmtree(stage, ignore_errors=True)
    (stage / "bin").mkdir(parents=True)
    (stage / "modules").mkdir()
    shutil.copy2(BUSYBOX, stage / "bin" / "busybox")
    names = []
    for path in modules:
        name = module_name(path.name)
        (stage / "modules" / f"{name}.ko").write_bytes(module_bytes(path))
        names.append(name)
    (stage / "modules" / "order").write_text("\n".join(names) + "\n")
    (stage / "init").write_text(init)
    (stage / "init").chmod(0o755)
    files = sorted(str(p.relative_to(stage)) for p in stage.rglob("*"))
    archive = subprocess.run(
        ["cpio", "--quiet", "-o", "-H", "newc"],
        cwd=stage,
        input="\n".join(files).encode(),
        capture_output=True,
        check=False,
    )
    if archive.returncode != 0:
        raise VmError(f"cpio failed: {archive.stderr.decode().strip()}")
    partial = initrd.with_suffix(".part")
    partial.write_bytes(gzip.compress(archive.stdout))
    partial.rename(initrd)
    shutil.rmtree(stage)
    log(f"initramfs {initrd.name}: {', '.join(names)}")
    return initrd


# ---------------------------------------------------------------- booting it


def qemu_command(kernel: Path, initrd: Path) -> list[str]:
    append = f"console=ttyS0 panic=-1 quiet loglevel=3 vcanroot={ROOT}"
    return [
        "qemu-system-x86_64",
        "-accel",
        "tcg",  # nested KVM hangs on these machines (docs/decisions/0028-vcan-suite-in-a-vm.md)
        "-m",
        "2G",
        "-smp",
        "2",
        "-nographic",
        "-monitor",
        "none",
        "-serial",
        "stdio",
        "-nic",
        "none",  # no network: the guest needs none
        "-no-reboot",
        "-kernel",
        str(kernel),
        "-initrd",
        str(initrd),
        "-append",
        append,
        "-virtfs",
        "local,path=/,mount_tag=host,security_model=none,id=host,multidevs=remap",
    ]


def _best_of_three(work: Callable[[], None]) -> float:
    best = float("inf")
    for _ in range(3):
        started = time.perf_counter()
        work()
        best = min(best, time.perf_counter() - started)
    return best


def _python_work() -> None:
    table: dict[int, int] = {}
    for i in range(200_000):
        table[i % 1000] = table.get(i % 1000, 0) + i * i


def _socket_work() -> None:
    """Frames through the kernel and back, as a CAN line's are: under TCG a system call
    costs far more, next to pure Python, than on the host."""
    a, b = socket.socketpair()
    with a, b:
        for _ in range(2_000):
            a.send(b"0123456789abcdef")
            b.recv(64)


def speed_probe() -> dict[str, float]:
    """Seconds for a fixed piece of pure Python and for a fixed number of socket round
    trips (the best of three each): the guest's figures over the host's say how much
    slower the VM runs right now."""
    return {"python": _best_of_three(_python_work), "socket": _best_of_three(_socket_work)}


def guest_time_scale(host_probe: dict[str, float] | float | None) -> float:
    """The larger of the two ratios, within [VM_TIME_SCALE, VM_TIME_SCALE_MAX]."""
    if not host_probe:
        return VM_TIME_SCALE
    host = host_probe if isinstance(host_probe, dict) else {"python": host_probe}
    guest = speed_probe()
    ratio = max(guest[k] / host[k] for k in host if host[k] > 0)
    log(
        "speed probe, guest over host: "
        + ", ".join(f"{k} {guest[k] / host[k]:.1f}" for k in host if host[k] > 0)
    )
    return float(min(max(VM_TIME_SCALE, math.ceil(ratio)), VM_TIME_SCALE_MAX))


def run_in_vm(extra: list[str]) -> int:
    if " " in str(ROOT):
        raise VmError(f"the project path {ROOT} has a space (it goes on the kernel line)")
    ensure_packages()
    CACHE.mkdir(exist_ok=True)
    tree, version = ensure_kernel()
    initrd = ensure_initrd(tree, version)
    kernel = tree / "boot" / f"vmlinuz-{version}"
    shutil.rmtree(RUN, ignore_errors=True)
    RUN.mkdir(parents=True)
    selection = extra or collect()
    ARGS.write_text(json.dumps({"pytest": selection, "host_probe": speed_probe()}))
    log(f"booting kernel {version} under TCG")
    started = time.monotonic()
    try:
        code = subprocess.run(
            qemu_command(kernel, initrd), stdin=subprocess.DEVNULL, timeout=VM_TIMEOUT, check=False
        ).returncode
    except subprocess.TimeoutExpired:
        log(f"the VM did not power off within {VM_TIMEOUT:g} s")
        return 1
    if code != 0:
        log(f"qemu exited with status {code}")
        return 1
    if not STATUS.exists():
        log("the tests did not run in the VM (no exit status came back)")
        return 1
    status = json.loads(STATUS.read_text())
    expected = None if extra else len(selection)
    return verdict(int(status["exit"]), started, "VM", expected)


def verdict(code: int, started: float, where: str, expected: int | None = None) -> int:
    """0 only when pytest passed, its report exists, something ran and nothing skipped."""
    seconds = time.monotonic() - started
    if not JUNIT.exists():
        log(f"no test report from the {where} run (pytest exit status {code})")
        return 1
    counts = junit_counts(JUNIT)
    log(f"vcan tests ({where}): {counts.text()} in {seconds:.0f} s")
    problems = []
    if code != 0:
        problems.append(f"pytest exit status {code}")
    if counts.tests == 0:
        problems.append("no vcan test ran")
    if expected is not None and counts.tests != expected:
        problems.append(f"{counts.tests} tests ran of the {expected} collected")
    if counts.skipped:
        problems.append(f"{counts.skipped} vcan tests skipped (each must run here)")
    if counts.failed or counts.errors:
        problems.append("failures")
    if problems:
        log("FAILED: " + "; ".join(problems))
        return 1
    return 0


def junit_counts(path: Path) -> Counts:
    root = ET.parse(path).getroot()
    suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))

    def total(key: str) -> int:
        return sum(int(s.get(key, "0")) for s in suites)

    return Counts(total("tests"), total("failures"), total("errors"), total("skipped"))


# ---------------------------------------------------------------- inside the VM


def guest() -> int:
    """In the VM: vcan0 up, the vcan tests, their exit status on the share for the host."""
    for cmd in (
        ["ip", "link", "set", "lo", "up"],
        ["ip", "link", "add", "dev", CHANNEL, "type", "vcan"],
        ["ip", "link", "set", "up", CHANNEL],
    ):
        subprocess.run(cmd, check=False)
    args = json.loads(ARGS.read_text()) if ARGS.exists() else {}
    scale = guest_time_scale(args.get("host_probe"))
    log(f"in the VM: the tests' time scale is {scale:g}")
    env = {**os.environ, "DRIVE_GATEWAY_TEST_TIME_SCALE": f"{scale:g}"}
    extra = args.get("pytest", [])
    code = subprocess.run(pytest_command(JUNIT, extra), cwd=ROOT, env=env, check=False).returncode
    with STATUS.open("w") as f:
        json.dump({"exit": code}, f)
        f.flush()
        os.fsync(f.fileno())
    return code


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.vcan_vm", description=__doc__)
    parser.add_argument("--guest", action="store_true", help="inside the VM (its /init)")
    parser.add_argument("--vm", action="store_true", help="use the VM even if this kernel can")
    parser.add_argument("pytest_args", nargs="*", help="after --: a narrower pytest selection")
    args = parser.parse_args(argv)
    if args.guest:
        return guest()
    problem = "--vm given" if args.vm else host_problem()
    if problem is None:
        log(f"this kernel has SocketCAN and {CHANNEL}: running the vcan tests here")
        return run_on_host(args.pytest_args)
    log(f"{problem}: running the vcan tests in a VM")
    try:
        return run_in_vm(args.pytest_args)
    except VmError as exc:
        log(f"FAILED: {exc}")
        return 1


if __name__ == "__main__":
    sys.exit(main())
