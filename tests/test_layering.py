"""The layer rules of docs/architecture.md ("Layers as folders"), checked on the import graph.

A module's layer is read from its path alone: its folder (``adapters/<bus>/codec/``,
``gateway/zenoh/``) or, at a bus package's top, its name (``contract.py``, ``adapter.py``).
So a new module follows the rules of the place it is put in. Imports under
``if TYPE_CHECKING:`` are annotations only and do not count.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

from gateway.devices import Device

ROOT = Path(__file__).resolve().parents[1]
FIELDBUS_LIBS = ("serial", "can", "canopen")
IO_MODULES: tuple[str, ...] = (*FIELDBUS_LIBS, "asyncio", "socket", "select", "selectors")
IO_MODULES += ("threading", "time", "subprocess", "zenoh", "pymodbus")

# ---------------------------------------------------------------- the folders

BUSES = ("profibus", "devicenet", "canopen")
# A device package of its own runs on another package's bus and uses its codecs and contract
# (from the registry: the MCD 600 on the Profibus master).
RUNS_ON = {
    (d.spec.package.split(".")[1], d.spec.bus)
    for d in Device
    if d.spec.package.count(".") == 1
    and d.spec.package.startswith("adapters.")
    and d.spec.package != f"adapters.{d.spec.bus}"
}
DEVICE_PACKAGES = tuple(sorted(own for own, _bus in RUNS_ON))
# The layers inside a bus package, from the bottom up: a folder's (or, at the package's top,
# a module's) name -> its floor. A module may import only its own floor and the ones below.
FLOORS = {
    "errors": 0,
    "codec": 1,
    "master": 2,  # the engines
    "scanner": 2,
    "link": 2,  # the bus's link settings on the shared medium
    "contract": 3,
    "options": 3,
    # 4: the devices (weg/, cfw08/, drive.py): any other name
    "sim": 5,
    "plan": 6,
    "driver": 6,
    "channel": 6,
    "adapter": 6,
    "adr": 6,
    "cli": 7,
}
DEVICE_FLOOR = 4
ENGINE_FOLDERS = ("master", "scanner")
SHARED_LINK = "adapters.link"  # the media
SHARED_CAN = "adapters.can"  # what both CAN buses share
CORE_SUBFOLDERS = (
    "gateway.runtime",
    "gateway.cli",
    "gateway.sim",
    *(f"gateway.{f}" for f in ("zenoh", "modbus", "web", "opcua")),
)
FRONT_ENDS = ("gateway.zenoh", "gateway.modbus", "gateway.web", "gateway.opcua")
CORE_PACKAGES = ("gateway.access", "gateway.history")
"""Folders of the core itself: who may do what (roles, users, sessions, the audit trail),
and the history service, which the front ends and the runtime read as they read the
hub. Held to the core's rules (:func:`core_rule`)."""
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
    "gateway.vendorfile",  # a drive's GSD or EDS file, read safely (options layer)
)


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


def package_of(mod: str) -> str | None:
    """``adapters.<pkg>`` of a bus or device package's module (None elsewhere)."""
    parts = mod.split(".")
    if len(parts) >= 2 and parts[0] == "adapters" and parts[1] in (*BUSES, *DEVICE_PACKAGES):
        return ".".join(parts[:2])
    return None


def floor(mod: str) -> int | None:
    """A bus or device package module's floor, from its path; None for the package itself."""
    parts = mod.split(".")
    if package_of(mod) is None or len(parts) < 3:
        return None
    if parts[1] in DEVICE_PACKAGES:  # a device package: its modules are the device
        return FLOORS[parts[2]] if parts[2] in ("sim", "cli") else DEVICE_FLOOR
    return FLOORS.get(parts[2], DEVICE_FLOOR)


def is_core(mod: str) -> bool:
    """A module of gateway/'s top: the core (the entry point ``__main__`` is not)."""
    return under(mod, "gateway") and not under(mod, *CORE_SUBFOLDERS, "gateway.__main__")


def is_simulator(mod: str) -> bool:
    """A simulator module: in a ``sim`` folder, or a simulated line (``adapters.can.simulated``)."""
    parts = mod.split(".")
    return "sim" in parts[1:] or parts[-1] == "simulated"


def violations(rule) -> list[str]:
    bad = []
    for mod, imports in MODULES.items():
        for imp in sorted(imports):
            why = rule(mod, imp)
            if why:
                bad.append(f"{mod} imports {imp}: {why}")
    return bad


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


# ---------------------------------------------------------------- gateway/


def core_rule(mod: str, imp: str) -> str | None:
    if not is_core(mod):
        return None
    if under(imp, "adapters"):
        return "the core never imports an adapter (use the name table)"
    if under(imp, *FIELDBUS_LIBS):
        return "no fieldbus library in the core"
    if under(imp, *CORE_SUBFOLDERS):
        return "the core imports no folder of gateway/ (front ends, runtime, cli, sim)"
    return None


def test_the_core_imports_no_subfolder_no_adapter_and_no_fieldbus_library() -> None:
    assert violations(core_rule) == []


HISTORY = "gateway.history"
"""The core's history service (docs/decisions/0083-history-store.md): a folder of the core,
not of CORE_SUBFOLDERS, so the front ends and the runtime read it as they read the hub."""


def test_the_history_is_a_core_service_and_the_only_user_of_sqlite() -> None:
    """gateway/history/ follows the core's rule (no front end, runtime, cli or adapter), and
    nothing outside it opens the history file: sqlite3 is imported there only."""

    def rule(mod: str, imp: str) -> str | None:
        if under(imp, "sqlite3") and not under(mod, HISTORY):
            return "the history file is opened by gateway.history only"
        if under(mod, HISTORY) and under(imp, *CORE_SUBFOLDERS, "adapters"):
            return "the history service imports the core only"
        return None

    assert is_core(f"{HISTORY}.store")
    assert violations(rule) == []


def test_the_core_packages_are_core_and_no_other_folder_is() -> None:
    folders = {
        ".".join(mod.split(".")[:2])
        for mod in MODULES
        if mod.count(".") >= 2 and under(mod, "gateway")
    }
    assert folders == set(CORE_SUBFOLDERS) | set(CORE_PACKAGES)
    assert all(is_core(mod) for mod in MODULES if under(mod, *CORE_PACKAGES))


def front_end_rule(mod: str, imp: str) -> str | None:
    if not under(mod, *FRONT_ENDS):
        return None
    own = ".".join(mod.split(".")[:2])
    if under(imp, "adapters", *FIELDBUS_LIBS):
        return "a front end reaches drives through the hub only"
    if under(imp, "gateway") and not is_core(imp) and not under(imp, own):
        return "a front end imports the core only (gateway.frontend for the runtime)"
    return None


def test_front_ends_import_the_core_only() -> None:
    assert violations(front_end_rule) == []


def test_the_runtime_and_the_simulation_support_stay_below_the_cli() -> None:
    def rule(mod: str, imp: str) -> str | None:
        if under(mod, "gateway.runtime") and under(imp, "gateway.cli"):
            return "the runtime is started by the command line, never the reverse"
        outside = under(imp, "gateway") and not is_core(imp) and not under(imp, "gateway.sim")
        if under(mod, "gateway.sim") and outside:
            return "the simulation support imports the core only"
        return None

    assert violations(rule) == []


# ---------------------------------------------------------------- adapters/


def test_every_bus_package_module_is_in_a_layer_folder() -> None:
    """At a bus package's top only the layer names of FLOORS (and its device packages) stand:
    a new file says its layer by where it is put."""
    stray = []
    for mod in MODULES:
        parts = mod.split(".")
        if package_of(mod) and parts[1] in BUSES and len(parts) == 3:
            path = ROOT.joinpath(*parts)
            if parts[2] not in FLOORS and not path.is_dir() and parts[2] != "drive":
                stray.append(mod)
    assert stray == []


def floor_rule(mod: str, imp: str) -> str | None:
    pkg = package_of(mod)
    if pkg is None or not under(imp, pkg) or imp == pkg:
        return None
    here, there = floor(mod), floor(imp)
    if here is not None and there is not None and there > here:
        return f"floor {here} imports floor {there}: a lower layer never imports a higher one"
    return None


def test_no_import_runs_back_up_inside_a_package() -> None:
    assert violations(floor_rule) == []


def codec_rule(mod: str, imp: str) -> str | None:
    pkg = package_of(mod)
    if pkg is None or not under(mod, f"{pkg}.codec"):
        return None
    if under(imp, "gateway") and not under(imp, "gateway.errors"):
        return "a codec imports nothing of the core but errors"
    own = (f"{pkg}.codec", f"{pkg}.errors", f"{SHARED_CAN}.frame", f"{SHARED_CAN}.bits")
    if under(imp, "adapters") and imp not in (pkg, SHARED_CAN) and not under(imp, *own):
        return "a codec imports only codecs and its bus's errors"
    if under(imp, *IO_MODULES) and not (under(imp, "canopen") and mod.endswith(".codec.od")):
        return "a codec is sans-IO"
    return None


def test_codecs_import_only_codecs_and_errors() -> None:
    assert violations(codec_rule) == []


def adapter_rule(mod: str, imp: str) -> str | None:
    pkg = package_of(mod)
    if pkg is None:
        return None
    if under(imp, "gateway") and not under(imp, *ADAPTER_MAY_IMPORT):
        return f"adapters may import only {', '.join(ADAPTER_MAY_IMPORT)} of the core"
    other = package_of(imp)
    own, bus = pkg.split(".")[1], (other or "..").split(".")[1]
    if other is not None and other != pkg and (own, bus) not in RUNS_ON:
        return "bus packages do not import each other (a device package uses its bus's)"
    return None


def test_adapters_import_only_their_package_the_shared_ones_and_the_adapter_contract() -> None:
    assert violations(adapter_rule) == []


def test_the_shared_packages_import_no_bus_package() -> None:
    """adapters.link knows media (pyserial, python-can), never a protocol; adapters.can holds
    what both CAN buses share and builds on the link; neither imports a bus package."""

    def rule(mod: str, imp: str) -> str | None:
        if under(mod, SHARED_LINK):
            if under(imp, "adapters") and imp != "adapters" and not under(imp, SHARED_LINK):
                return "the shared link layer imports no other package of adapters/"
            if under(imp, "gateway") and not under(imp, *SHARED_LINK_MAY_IMPORT):
                return "the shared link layer imports only gateway.errors of the core"
        if under(mod, SHARED_CAN):
            if package_of(imp) is not None:
                return "what the CAN buses share imports neither of them"
            if under(imp, "gateway") and not under(imp, *ADAPTER_MAY_IMPORT):
                return "adapters.can imports only the core contract"
        return None

    assert violations(rule) == []


# The canopen library reads a drive's object dictionary (EDS/DCF) and encodes its values
# (adapters.canopen.codec.od); the simulator is built on its LocalNode. Neither opens a
# network: the master's frames go through the shared link
# (docs/decisions/0045-canopen-master-own-engine.md).
CANOPEN_LIBRARY_USERS = ("adapters.canopen.codec.od", "adapters.canopen.sim")


def test_the_fieldbus_libraries_are_the_shared_link_layers() -> None:
    """One link per medium: pyserial and python-can are imported by adapters.link, and by a
    bus's own link module only for its settings (8E1, the CAN frame it carries). The CANopen
    simulator is the exception: a device built on the canopen library's LocalNode on a
    python-can bus of its own, never the gateway's link."""
    own_links = [f"adapters.{bus}.link" for bus in BUSES]

    def rule(mod: str, imp: str) -> str | None:
        if under(imp, "canopen") and under(mod, *CANOPEN_LIBRARY_USERS):
            return None
        allowed = (SHARED_LINK, *own_links, "adapters.canopen.sim")
        if under(imp, *FIELDBUS_LIBS) and not under(mod, *allowed):
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


def simulator_rule(mod: str, imp: str) -> str | None:
    """Simulators are chosen by the composition root (gateway.runtime gives a simulated line
    for ``simulate = true``); an adapter's own modules never import one. Its command-line
    tools (``drive-gateway sim ...``) run simulators on purpose."""
    if not under(mod, "adapters") or is_simulator(mod) or mod.rpartition(".")[2] == "cli":
        return None
    if under(imp, "adapters") and is_simulator(imp):
        return "a production adapter module imports no simulator (the runtime chooses it)"
    return None


def test_production_adapters_import_no_simulator() -> None:
    assert violations(simulator_rule) == []


def test_the_simulator_rule_sees_a_lazy_import(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """An import inside a method is one (every import counts, not only the module's top
    level); a simulator or a CLI may import one."""
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    probe = tmp_path / "adapters" / "profibus" / "adapter.py"
    probe.parent.mkdir(parents=True)
    probe.write_text("def start():\n    from .sim.devices import SIM_DEVICES\n")
    found = imports_of(probe)
    assert "adapters.profibus.sim.devices" in found
    assert simulator_rule("adapters.profibus.adapter", "adapters.profibus.sim.devices")
    assert simulator_rule("adapters.devicenet.adapter", "adapters.mcd600.sim.starter")
    assert simulator_rule("adapters.devicenet.adapter", "adapters.can.simulated")
    assert simulator_rule("adapters.profibus.sim.simulated", "adapters.profibus.sim.line") is None
    assert simulator_rule("adapters.profibus.cli", "adapters.profibus.sim.port") is None
    assert simulator_rule("gateway.runtime.daemon", "adapters.profibus.sim.simulated") is None


def test_engines_are_sans_io_all_the_way_down() -> None:
    """An engine is stepped with an injected clock: nothing it reaches does I/O or reads
    the time, and it reaches no link settings, contract, device, simulator or adapter."""
    bad = []
    engines = [f"adapters.{bus}.{f}" for bus in BUSES for f in ENGINE_FOLDERS]
    for engine in [e for e in engines if e in MODULES]:
        closure = reachable([m for m in MODULES if under(m, engine)])
        for mod in sorted(closure):
            for imp in sorted(MODULES[mod]):
                if under(imp, *IO_MODULES):
                    bad.append(f"{engine} reaches {mod}, which imports {imp} (I/O or clock)")
                elif under(imp, "gateway") and not under(imp, "gateway.errors"):
                    bad.append(f"{engine} reaches {mod}, which imports {imp} (core)")
            level = floor(mod)
            if (level is not None and level >= FLOORS["link"] and not under(mod, engine)) or (
                under(mod, f"{SHARED_CAN}.adapter", f"{SHARED_CAN}.simulated")
            ):
                bad.append(f"{engine} reaches {mod} (above the codecs)")
    assert bad == []


def test_simulators_never_import_engines() -> None:
    def rule(mod: str, imp: str) -> str | None:
        engine = floor(imp) == FLOORS["master"] and imp.split(".")[2] in ENGINE_FOLDERS
        if is_simulator(mod) and package_of(imp) and engine:
            return "a simulator is built from codecs and profiles, never the engine"
        return None

    assert violations(rule) == []


# ---------------------------------------------------------------- the checker itself


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


def test_the_rules_read_the_layer_from_the_path() -> None:
    """Each rule fires on a made-up import that breaks it: no rule is empty."""
    assert floor("adapters.profibus.codec.fdl") == FLOORS["codec"]
    assert floor("adapters.devicenet.cfw08.profile") == DEVICE_FLOOR
    assert floor("adapters.mcd600.options") == DEVICE_FLOOR
    assert floor("adapters.mcd600.sim.starter") == FLOORS["sim"]
    assert floor_rule("adapters.profibus.codec.fdl", "adapters.profibus.master.engine")
    assert floor_rule("adapters.canopen.master.engine", "adapters.canopen.adapter")
    assert floor_rule("adapters.canopen.adapter", "adapters.canopen.master.engine") is None
    assert codec_rule("adapters.canopen.codec.frames", "asyncio")
    assert codec_rule("adapters.devicenet.codec.ids", "adapters.devicenet.scanner.engine")
    assert codec_rule("adapters.devicenet.codec.ids", "gateway.errors") is None
    assert adapter_rule("adapters.devicenet.adapter", "adapters.canopen.codec.frames")
    assert adapter_rule("adapters.mcd600.profile", "adapters.profibus.contract") is None
    assert adapter_rule("adapters.canopen.adapter", "gateway.hub")
    assert core_rule("gateway.hub", "gateway.runtime.daemon")
    assert core_rule("gateway.hub", "adapters.profibus.adapter")
    assert core_rule("gateway.__main__", "gateway.cli") is None
    assert front_end_rule("gateway.web.metrics", "gateway.runtime.daemon")
    assert front_end_rule("gateway.zenoh.frontend", "gateway.modbus.map")
    assert front_end_rule("gateway.web.metrics", "gateway.frontend") is None
    assert front_end_rule("gateway.opcua.frontend", "gateway.web.views")
    assert front_end_rule("gateway.opcua.frontend", "gateway.runtime.daemon")
    assert front_end_rule("gateway.opcua.commands", "gateway.hub") is None
    assert core_rule("gateway.opcuaconfig", "gateway.opcua.space")
