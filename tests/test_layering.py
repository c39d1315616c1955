"""The layering rules of ARCHITECTURE.md, checked on the import graph.

Imports under ``if TYPE_CHECKING:`` are annotations only and do not count.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

from gateway.devices import Device

ROOT = Path(__file__).resolve().parents[1]
FIELDBUS_LIBS = ("serial", "can", "canopen")
# Codec modules: sans-IO, may import only their own codec siblings and gateway.errors.
CODEC_NAMES = {
    "adapters.profibus": (
        "fdl",
        "dp",
        "dpv1",
        "profidrive",
        "wegrecord",
        "diag",
        "chkcfg",
        "errors",
        "_pdu",
    ),
    "adapters.devicenet": (
        "ids",
        "explicit",
        "fragment",
        "dupmac",
        "cip",
        "objects",
        "datatypes",
        "frame",
        "errors",
        "_validate",
        "eds",
    ),
    "adapters.canopen": ("frames", "cia402", "codes", "errors"),
}
# The device packages inside a bus package (from the registry): not codecs either.
DEVICE_PARTS = tuple(
    sorted(
        {
            d.spec.package.split(".")[2]
            for d in Device
            if d.spec.package.count(".") >= 2 and not d.spec.test
        }
    )
)
# Parts of an adapter package that are not codecs: a codec may not import them.
NON_CODEC_NAMES = ("master", "link", "scanner", "adapter", "sim", "cli", "engine", *DEVICE_PARTS)
ENGINE_NAMES = ("adapters.profibus.master", "adapters.devicenet.scanner", "adapters.canopen.master")
# The link layer every bus adapter shares (one link per medium, one driver loop per medium).
SHARED_LINK = "adapters.link"
SHARED_LINK_MAY_IMPORT = (*FIELDBUS_LIBS, "gateway.errors")
ADAPTER_MAY_IMPORT = (
    "gateway.model",
    "gateway.errors",
    "gateway.adapter",
    "gateway.schema",
    "gateway.config",
    "gateway.sim",
    "gateway.devices",
    "gateway.loader",
)
# A device package of its own runs on another package's bus and uses its codecs (from the
# registry: the MCD 600 on the Profibus master).
RUNS_ON = {
    (d.spec.package.split(".")[1], d.spec.bus)
    for d in Device
    if d.spec.package.count(".") == 1 and d.spec.package.startswith("adapters.")
}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def imports_of(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    package = module_name(path)
    if path.name != "__init__.py":
        package = package.rpartition(".")[0]
    found: set[str] = set()

    def visit(nodes: list[ast.stmt]) -> None:
        for node in nodes:
            if isinstance(node, ast.If) and _is_type_checking(node):
                visit(node.orelse)
                continue
            for child in ast.walk(node):
                if isinstance(child, ast.Import):
                    found.update(alias.name for alias in child.names)
                elif isinstance(child, ast.ImportFrom):
                    base = child.module or ""
                    if child.level:
                        anchor = package.split(".")
                        anchor = anchor[: len(anchor) - (child.level - 1)]
                        base = ".".join([*anchor, base] if base else anchor)
                    found.add(base)
                    found.update(f"{base}.{alias.name}" for alias in child.names)

    visit(tree.body)
    return found


def project_modules() -> dict[str, set[str]]:
    out = {}
    for top in ("gateway", "adapters"):
        for path in sorted((ROOT / top).rglob("*.py")):
            out[module_name(path)] = imports_of(path)
    return out


MODULES = project_modules()


def under(name: str, *prefixes: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def violations(rule) -> list[str]:
    bad = []
    for mod, imports in MODULES.items():
        for imp in sorted(imports):
            why = rule(mod, imp)
            if why:
                bad.append(f"{mod} imports {imp}: {why}")
    return bad


def test_core_imports_no_adapter_and_no_fieldbus_library() -> None:
    composition = ("gateway.daemon", "gateway.cli", "gateway.__main__", "gateway.simcli")

    def rule(mod: str, imp: str) -> str | None:
        if not under(mod, "gateway") or under(mod, *composition):
            return None
        if under(imp, "adapters"):
            return "the core never imports an adapter (use the name table)"
        if under(imp, *FIELDBUS_LIBS):
            return "no fieldbus library in the core"
        return None

    assert violations(rule) == []


def test_codecs_import_only_codecs_and_errors() -> None:
    def rule(mod: str, imp: str) -> str | None:
        for pkg, names in CODEC_NAMES.items():
            codecs = [f"{pkg}.{n}" for n in names]
            if under(mod, *codecs):
                if under(imp, "gateway") and not under(imp, "gateway.errors"):
                    return "a codec imports nothing of the project but errors"
                upper = [f"{pkg}.{n}" for n in NON_CODEC_NAMES]
                if under(imp, "adapters") and (not under(imp, pkg) or under(imp, *upper)):
                    return "a codec imports only other codecs"
                if under(imp, *FIELDBUS_LIBS, "asyncio", "zenoh", "pymodbus"):
                    return "a codec is sans-IO"
        return None

    assert violations(rule) == []


def test_adapters_import_only_their_package_and_the_adapter_contract() -> None:
    def rule(mod: str, imp: str) -> str | None:
        if not under(mod, "adapters"):
            return None
        if under(imp, "gateway") and not under(imp, *ADAPTER_MAY_IMPORT):
            return f"adapters may import only {', '.join(ADAPTER_MAY_IMPORT)} of the core"
        own = mod.split(".")[1] if mod.count(".") >= 1 else ""
        if under(imp, "adapters") and imp != "adapters":
            other = imp.split(".")[1]
            # the shared link layer is every bus adapter's; a device runs on its bus's codecs
            shared = under(imp, SHARED_LINK) or (own, other) in RUNS_ON
            if other != own and not shared:
                return "adapters do not import each other"
        return None

    assert violations(rule) == []


def test_the_shared_link_layer_imports_no_bus_adapter() -> None:
    """adapters.link knows media (pyserial, python-can), never a protocol: the bus adapters
    give it their codecs and engines, and it imports none of them nor the core."""

    def rule(mod: str, imp: str) -> str | None:
        if not under(mod, SHARED_LINK):
            return None
        if under(imp, "adapters") and imp != "adapters" and not under(imp, SHARED_LINK):
            return "the shared link layer imports no bus adapter"
        if under(imp, "gateway") and not under(imp, *SHARED_LINK_MAY_IMPORT):
            return "the shared link layer imports only gateway.errors of the core"
        return None

    assert violations(rule) == []


# The canopen library reads a drive's object dictionary (EDS/DCF) and encodes its values
# (adapters.canopen.od); the simulator is built on its LocalNode. Neither opens a network:
# the master's frames go through the shared link (docs/decisions.md).
CANOPEN_LIBRARY_USERS = ("adapters.canopen.od", "adapters.canopen.sim")


def test_the_fieldbus_libraries_are_the_shared_link_layers() -> None:
    """One link per medium: pyserial and python-can are imported by adapters.link, and by a
    bus's own link module only for its settings (8E1, the CAN frame it carries). The CANopen
    simulator is the exception: a device built on the canopen library's LocalNode (issue 22)
    on a python-can bus of its own, never the gateway's link."""
    own_links = [f"{pkg}.link" for pkg in CODEC_NAMES]
    library_devices = ("adapters.canopen.sim",)

    def rule(mod: str, imp: str) -> str | None:
        if under(imp, "canopen") and under(mod, *CANOPEN_LIBRARY_USERS):
            return None
        if under(imp, *FIELDBUS_LIBS) and not under(mod, SHARED_LINK, *own_links, *library_devices):
            return "a fieldbus library only in adapters.link (and a bus's link settings)"
        return None

    assert violations(rule) == []


@pytest.mark.parametrize(
    ("adapter", "loop"),
    [
        ("adapters.profibus.adapter", f"{SHARED_LINK}.stream"),
        ("adapters.devicenet.adapter", f"{SHARED_LINK}.candriver"),
        ("adapters.canopen.adapter", f"{SHARED_LINK}.candriver"),
    ],
)
def test_each_bus_adapter_runs_on_its_mediums_driver_loop(adapter: str, loop: str) -> None:
    assert loop in reachable([adapter])


def is_simulator(mod: str) -> bool:
    """A simulator module: in a ``sim`` package or named ``sim`` (adapters.mcd600.sim)."""
    return "sim" in mod.split(".")[1:]


def simulator_rule(mod: str, imp: str) -> str | None:
    """Simulators are chosen by the composition root (gateway.daemon gives a simulated line
    for ``simulate = true``); an adapter's own modules never import one. Its command-line
    tools (``drive-gateway sim ...``) run simulators on purpose."""
    if not under(mod, "adapters") or is_simulator(mod) or mod.rpartition(".")[2] == "cli":
        return None
    if under(imp, "adapters") and is_simulator(imp):
        return "a production adapter module imports no simulator (the daemon chooses it)"
    return None


def test_production_adapters_import_no_simulator() -> None:
    assert violations(simulator_rule) == []


def test_the_simulator_rule_sees_a_lazy_import(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """The import adapters/profibus/adapter.py had, inside a method, is one (every import
    counts, not only the module's top level); a simulator or a CLI may import one."""
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    probe = tmp_path / "adapters" / "profibus" / "adapter.py"
    probe.parent.mkdir(parents=True)
    probe.write_text("def start():\n    from .sim.devices import SIM_DEVICES\n")
    found = imports_of(probe)
    assert "adapters.profibus.sim.devices" in found
    assert simulator_rule("adapters.profibus.adapter", "adapters.profibus.sim.devices")
    assert simulator_rule("adapters.devicenet.adapter", "adapters.mcd600.sim")
    assert simulator_rule("adapters.profibus.sim.simulated", "adapters.profibus.sim.line") is None
    assert simulator_rule("adapters.profibus.cli", "adapters.profibus.sim.port") is None
    assert simulator_rule("gateway.daemon", "adapters.profibus.sim.simulated") is None


IO_MODULES: tuple[str, ...] = (*FIELDBUS_LIBS, "asyncio", "socket", "select", "selectors")
IO_MODULES += ("threading", "time", "subprocess", "zenoh", "pymodbus")


def reachable(roots: list[str]) -> set[str]:
    """The project modules ``roots`` import, directly or through other project modules."""
    seen: set[str] = set()
    todo = list(roots)
    while todo:
        mod = todo.pop()
        if mod in seen:
            continue
        seen.add(mod)
        todo.extend(imp for imp in MODULES[mod] if imp in MODULES)
    return seen


def test_engines_are_sans_io_all_the_way_down() -> None:
    """An engine is stepped with an injected clock: nothing it reaches does I/O or reads
    the time, and it reaches no link, adapter, simulator or profile."""
    upper = [f"{pkg}.{n}" for pkg in CODEC_NAMES for n in NON_CODEC_NAMES]
    bad = []
    for engine in ENGINE_NAMES:
        closure = reachable([m for m in MODULES if under(m, engine)])
        for mod in sorted(closure):
            for imp in sorted(MODULES[mod]):
                if under(imp, *IO_MODULES):
                    bad.append(f"{engine} reaches {mod}, which imports {imp} (I/O or clock)")
                elif under(imp, "gateway") and not under(imp, "gateway.errors"):
                    bad.append(f"{engine} reaches {mod}, which imports {imp} (core)")
            if under(mod, *upper) and not under(mod, engine):
                bad.append(f"{engine} reaches {mod} (not a codec)")
    assert bad == []


def test_simulators_never_import_engines() -> None:
    def rule(mod: str, imp: str) -> str | None:
        if ".sim" in mod and under(imp, *ENGINE_NAMES):
            return "a simulator is built from codecs and profiles, never the engine"
        return None

    assert violations(rule) == []


def test_front_ends_do_not_import_each_other() -> None:
    def rule(mod: str, imp: str) -> str | None:
        if under(mod, "gateway.zenoh") and under(imp, "gateway.modbus"):
            return "front ends are independent"
        if under(mod, "gateway.modbus") and under(imp, "gateway.zenoh"):
            return "front ends are independent"
        return None

    assert violations(rule) == []


def test_the_checker_sees_imports_but_not_type_checking_ones(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    probe = tmp_path / "gateway" / "probe.py"
    probe.parent.mkdir()
    probe.write_text(
        "import serial\nfrom . import hub\nfrom typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    import can\n"
    )
    found = imports_of(probe)
    assert {"serial", "gateway", "gateway.hub"} <= found
    assert "can" not in found
