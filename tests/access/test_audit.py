"""The audit trail: CR 2.8's fields, a file of bounded size, the journal's datagrams."""

from __future__ import annotations

import json
import socket
from pathlib import Path

from gateway.access.audit import AuditSection, AuditTrail, Category, Kind, Result
from gateway.access.journal import decode
from gateway.access.roles import Identity, Role

ANA = Identity("ana", Role.OPERATOR)


def test_a_record_has_the_fields_cr_2_8_lists() -> None:
    trail = AuditTrail(clock=lambda: 1_700_000_000.25)
    rec = trail.record(
        Kind.COMMAND, Result.SUCCESS, interface="web", peer="10.0.0.9", identity=ANA, detail="run"
    )
    assert rec is not None
    assert rec.to_json() == {
        "seq": 1,
        "timestamp": "2023-11-14T22:13:20.250Z",
        "interface": "web",
        "peer": "10.0.0.9",
        "identity": "ana",
        "role": "operator",
        "category": "control",
        "type": "command",
        "event_id": 2001,
        "result": "success",
        "detail": "run",
    }
    assert rec is not None and trail.newest() == [rec.to_json()]
    assert trail.counts == {"command:success": 1}


def test_event_ids_are_unique_and_each_kind_has_a_category() -> None:
    ids = [k.event_id for k in Kind]
    assert len(ids) == len(set(ids))
    assert {k.category for k in Kind} == set(Category)


def test_an_outsiders_text_cannot_forge_a_line_or_grow_a_record() -> None:
    trail = AuditTrail()
    rec = trail.record(
        Kind.LOGIN,
        Result.FAILURE,
        interface="web",
        peer="p" * 500,
        identity='evil\n{"result": "success"}',
        detail="x" * 5000,
    )
    assert rec is not None
    assert "\n" not in rec.identity and len(rec.peer) <= 120 and len(rec.detail) <= 300


def test_the_newest_since_a_sequence_number() -> None:
    trail = AuditTrail()
    for _ in range(5):
        trail.record(Kind.LOGOUT, Result.SUCCESS, interface="web")
    assert [r["seq"] for r in trail.newest(limit=2)] == [4, 5]
    assert [r["seq"] for r in trail.newest(since=3)] == [4, 5]


def test_the_file_is_json_lines_and_its_size_bounded(tmp_path: Path) -> None:
    path = tmp_path / "audit.log"
    trail = AuditTrail(AuditSection(file=path, max_kib=16, backups=2, journal=False))
    for i in range(1000):
        trail.record(Kind.COMMAND, Result.SUCCESS, interface="modbus", detail=f"write {i}")
    trail.close()
    files = sorted(tmp_path.iterdir())
    assert [f.name for f in files] == ["audit.log", "audit.log.1", "audit.log.2"]
    assert all(f.stat().st_size <= 16 * 1024 for f in files)
    last = json.loads(path.read_text().splitlines()[-1])
    assert last["detail"] == "write 999" and last["event_id"] == 2001


def test_records_go_to_the_journal_as_fields(tmp_path: Path) -> None:
    where = tmp_path / "journal.sock"
    journald = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    journald.bind(str(where))
    try:
        trail = AuditTrail(AuditSection(journal=True), journal_path=str(where))
        assert trail.journal_open
        trail.record(Kind.LOGIN, Result.FAILURE, interface="web", peer="10.0.0.9", identity="x")
        journald.settimeout(5)
        fields = decode(journald.recv(65536))
        trail.close()
    finally:
        journald.close()
    assert fields["AUDIT_TYPE"] == "login" and fields["AUDIT_RESULT"] == "failure"
    assert fields["AUDIT_EVENT_ID"] == "1001" and fields["AUDIT_PEER"] == "10.0.0.9"
    assert fields["SYSLOG_IDENTIFIER"] == "drive-gateway" and fields["PRIORITY"] == "4"
    assert fields["MESSAGE"].startswith("audit login failure: web 10.0.0.9 x")


def test_no_journal_socket_no_journal(tmp_path: Path) -> None:
    trail = AuditTrail(AuditSection(journal=True), journal_path=str(tmp_path / "none"))
    assert not trail.journal_open
    trail.record(Kind.LOGOUT, Result.SUCCESS, interface="web")  # no error
    assert len(trail.records) == 1


def test_a_flood_of_refusals_is_folded_per_peer_and_counted() -> None:
    now = [0.0]
    trail = AuditTrail(monotonic=lambda: now[0])

    def refuse(peer: str, who: str = "vic") -> None:
        trail.record(
            Kind.REFUSED, Result.FAILURE, interface="modbus", peer=peer, identity=who, detail="w"
        )

    for _ in range(500):
        refuse("10.0.0.9")
    refuse("10.0.0.8")  # another peer: its own record
    refuse("10.0.0.9", who="ana")  # another identity: its own record
    trail.record(Kind.LOGIN, Result.FAILURE, interface="web", peer="10.0.0.9")  # never folded
    trail.record(Kind.LOGIN, Result.FAILURE, interface="web", peer="10.0.0.9")
    assert [(r["peer"], r["identity"]) for r in trail.newest() if r["type"] == "refused"] == [
        ("10.0.0.9", "vic"),
        ("10.0.0.8", "vic"),
        ("10.0.0.9", "ana"),
    ]
    assert trail.counts["refused:failure"] == 502 and trail.counts["login:failure"] == 2
    now[0] = 5.0
    trail.flush()  # the period is not over: nothing yet
    assert len(trail.records) == 5
    now[0] = 10.5
    trail.flush()
    summary = trail.newest()[-1]
    assert (summary["type"], summary["peer"], summary["identity"]) == ("refused", "10.0.0.9", "vic")
    assert summary["detail"] == "499 more refused since the last record"
    refuse("10.0.0.9")  # the summary began a period: counted
    now[0] = 21.0
    refuse("10.0.0.9")
    assert trail.newest()[-1]["detail"] == "w (1 more since the last record)"


def test_every_web_refusal_line_takes_a_peer_and_a_figure() -> None:
    from gateway.web.admission import REFUSALS

    for kind, refusal in REFUSALS.items():
        assert (refusal.line % ("10.0.0.1", 5)).startswith("web"), kind


def test_setpoints_are_folded_per_drive_and_client_and_edges_never() -> None:
    from gateway.model import DriveCommand

    now = [0.0]
    trail = AuditTrail(monotonic=lambda: now[0])

    def command(cmd: DriveCommand, drive: str = "d1") -> None:
        trail.command(
            cmd, Result.SUCCESS, interface="modbus", peer="10.0.0.9", identity=ANA, drive=drive
        )

    for rpm in range(100):
        command(DriveCommand(speed_rpm=float(rpm)))
    command(DriveCommand(speed_rpm=5.0), drive="d2")  # another drive: its own record
    command(DriveCommand(run=True))  # an edge: always
    command(DriveCommand(run=False))
    details = [r["detail"] for r in trail.newest()]
    assert details == [
        'drive d1: {"speed_rpm":0.0}',
        'drive d2: {"speed_rpm":5.0}',
        'drive d1: {"run":true}',
        'drive d1: {"run":false}',
    ]
    now[0] = 11.0
    trail.flush()
    summary = trail.newest()[-1]
    assert (summary["type"], summary["result"]) == ("command", "success")
    assert summary["detail"] == "setpoint d1: 99 more since the last record"
    assert trail.counts["command:success"] == 103
