"""The page as first served: the drive table and the header's counts in the HTML itself
(shown before, and without, the script), faulted drives counted as such, codes as the
device's documents write them (0x8130 for a CANopen EMCY code), every value escaped."""

from __future__ import annotations

import re
from html.parser import HTMLParser
from pathlib import Path

from gateway.hub import DrivePolicy
from gateway.model import CommState, Device, DriveState, DriveStatus
from gateway.web.page import COLUMNS, counts, summary_text
from tests.web.harness import small_gateway, web_section

STATIC = Path(__file__).resolve().parents[2] / "gateway" / "web" / "static"


class Table(HTMLParser):
    """The drive rows' cell texts and the header's summary, as a browser without script
    shows them."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: dict[str, dict[str, str]] = {}
        self.summary = ""
        self.heads: list[str] = []
        self._row: str | None = None
        self._col: str | None = None
        self._in: str | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "tr" and a.get("data-drive"):
            self._row = a["data-drive"]
            self.rows[self._row or ""] = {}
        elif tag == "td" and self._row is not None:
            self._col = a.get("data-col")
            self.rows[self._row][self._col or ""] = ""
        elif tag == "th":
            self.heads.append(a.get("data-col") or "")
        elif tag == "div" and a.get("id") == "summary":
            self._in = "summary"

    def handle_endtag(self, tag: str) -> None:
        if tag == "td":
            self._col = None
        elif tag == "tr":
            self._row = None
        elif tag == "div":
            self._in = None

    def handle_data(self, data: str) -> None:
        if self._row is not None and self._col is not None:
            self.rows[self._row][self._col] += data
        elif self._in == "summary":
            self.summary += data


async def test_the_first_html_holds_the_drives_and_counts_the_faulted() -> None:
    async with small_gateway(web_section(), drives=("d1", "d2", "d3")) as gw:
        hub = gw.hub
        hub.add_drive(
            DriveState(id="co", device=Device.CIA402, bus="can", address=5), DrivePolicy()
        )
        hub.update("co", comm=CommState.ONLINE, status=DriveStatus.READY)
        hub.update("co", status=DriveStatus.FAULTED, fault_code=0x8130, fault_text="<life guard>")
        hub.update("d2", status=DriveStatus.FAULTED, fault_code=21, fault_text="undervoltage")
        hub.update("d3", comm=CommState.OFFLINE)
        async with gw.http.get(gw.url) as r:
            assert r.status == 200 and r.content_type == "text/html"
            text = await r.text()
    page = Table()
    page.feed(text)
    assert page.summary == "4 drives: 1 ok, 2 faulted, 1 offline"  # never "4 of 4 online"
    assert page.heads == [key for key, _ in COLUMNS]
    assert sorted(page.rows) == ["co", "d1", "d2", "d3"]
    assert page.rows["co"]["fault"] == "0x8130: <life guard>"  # hex; the text escaped
    assert "<life guard>" not in text and "&lt;life guard&gt;" in text
    assert page.rows["d2"]["fault"] == "21: undervoltage"  # a WEG fault number stays decimal
    assert page.rows["co"]["status"] == "faulted" and page.rows["d3"]["comm"] == "offline"
    assert page.rows["co"]["where"] == "can / 5"


def test_the_script_has_the_same_columns_and_counts() -> None:
    script = (STATIC / "app.js").read_text()
    listed = re.search(r"const COLUMNS = \[(.*?)\];", script, re.S)
    assert listed is not None
    pairs = re.findall(r'\["([a-z]+)", "([^"]+)"\]', listed.group(1))
    assert tuple(pairs) == COLUMNS
    assert "c.drives} drives: ${c.ok} ok, ${c.faulted} faulted, ${c.offline} offline" in script
    assert "fault_code_text" in script and "of ${h.drives} drives online" not in script


def test_counts() -> None:
    states = [
        DriveState(id="a", device=Device.TEST, bus="b", address=1, comm=CommState.ONLINE),
        DriveState(
            id="b",
            device=Device.TEST,
            bus="b",
            address=2,
            comm=CommState.ONLINE,
            status=DriveStatus.TRIPPED,
        ),
        DriveState(id="c", device=Device.TEST, bus="b", address=3),
    ]
    assert summary_text(counts(states)) == "3 drives: 1 ok, 1 faulted, 1 offline"
