"""The status page in a real browser: Debian's Chromium, headless, driven by Playwright.

Run by ``make test-web`` (marker ``browser``; ``make test`` leaves them out), which installs
Debian's chromium when it is missing. No browser is downloaded: Playwright starts the
system Chromium (``DRIVE_GATEWAY_CHROMIUM``, default /usr/bin/chromium) with a fresh
profile. Screenshots go to artefacts/web/ (git-ignored).
"""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
import pytest_asyncio
from playwright.async_api import Page, async_playwright

from gateway.access.passwords import hash_password
from gateway.access.roles import Role
from gateway.access.users import User
from gateway.model import CommState, Device, DriveState, DriveStatus, Source
from gateway.web.feed import PUSH_PERIOD
from tests.support.simulated import sim_runner
from tests.support.timing import scaled
from tests.web.harness import (
    ARTEFACTS,
    DEMO_DRIVES,
    TIMEOUT,
    TOKEN,
    TOKEN_SHA256,
    demo_daemon,
    small_gateway,
    web_section,
)

pytestmark = pytest.mark.browser

CHROMIUM = os.environ.get("DRIVE_GATEWAY_CHROMIUM", "/usr/bin/chromium")
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
WAIT_MS = TIMEOUT * 1000
SHOWN_WITHIN = scaled(1.0)  # s: a command over Zenoh shows in the table and trend (issue 23)


def chromium() -> str:
    if not os.access(CHROMIUM, os.X_OK):
        pytest.fail(f"{CHROMIUM} is missing: `make test-web` installs Debian's chromium")
    return CHROMIUM


@pytest_asyncio.fixture
async def page(tmp_path: Path) -> AsyncIterator[Page]:
    executable = chromium()
    async with async_playwright() as pw:
        context = await pw.chromium.launch_persistent_context(
            str(tmp_path / "profile"),
            executable_path=executable,
            headless=True,
            args=FLAGS,
            viewport={"width": 1280, "height": 900},
            # the test's own probes are evaluated scripts, which the page's CSP forbids; the
            # escaping test so shows the page escapes by itself, not by its CSP
            bypass_csp=True,
        )
        try:
            page = context.pages[0] if context.pages else await context.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            yield page
            assert not errors, errors
        finally:
            await context.close()
    # Playwright starts its driver through the loop's default executor: its thread ends here
    await asyncio.get_running_loop().shutdown_default_executor()


async def screenshot(page: Page, name: str) -> None:
    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    await page.screenshot(path=str(ARTEFACTS / f"{name}.png"), full_page=True)


def keep(line: str) -> None:
    """A measured figure, kept beside the screenshots."""
    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    with open(ARTEFACTS / "figures.txt", "a", encoding="utf-8") as f:
        f.write(line)


async def rows(page: Page) -> list[str]:
    ids: list[str] = await page.eval_on_selector_all(
        "#drives-body tr", "trs => trs.map(tr => tr.dataset.drive)"
    )
    return ids


async def open_page(page: Page, url: str, drives: int) -> None:
    await page.goto(url)
    await page.wait_for_selector('#drives-body[data-rendered="feed"]', timeout=WAIT_MS)
    await page.wait_for_function(
        f"document.querySelectorAll('#drives-body tr').length === {drives}", timeout=WAIT_MS
    )
    await page.wait_for_selector('#link[data-state="live"]', timeout=WAIT_MS)


async def test_the_page_shows_the_demo_live(page: Page) -> None:
    async with demo_daemon() as demo:
        await open_page(page, demo.url, len(DEMO_DRIVES))
        assert await rows(page) == list(DEMO_DRIVES)
        for drive in DEMO_DRIVES:
            row = page.locator(f'#drives-body tr[data-drive="{drive}"]')
            assert await row.get_attribute("data-comm") == "online"
        stations = await page.eval_on_selector_all(
            "#buses .bus",
            "bs => bs.map(b => [b.dataset.bus, b.querySelectorAll('.station').length])",
        )
        assert stations == [["profibus", 4], ["devicenet", 1], ["canopen", 2]]
        await page.wait_for_selector(  # the CANopen line's cycles are its SYNCs
            '#buses .bus[data-bus="canopen"] [data-fig="cycles"]', timeout=WAIT_MS
        )
        await page.wait_for_function(
            "document.querySelector('#health').textContent.includes('profibus')", timeout=WAIT_MS
        )
        await page.wait_for_function(  # the trends fill from the daemon's history
            "[...document.querySelectorAll('.trend')].every(t => Number(t.dataset.points) > 0)",
            timeout=WAIT_MS,
        )
        assert await page.locator("#events li").count() > 0
        await screenshot(page, "demo-desktop")
        await page.set_viewport_size({"width": 390, "height": 844})  # a phone in the plant
        await asyncio.sleep(PUSH_PERIOD * 2)
        width = await page.evaluate("document.documentElement.scrollWidth")
        assert width <= 390 + 1, "the page scrolls sideways on a phone"
        await screenshot(page, "demo-phone")


async def test_a_run_command_over_zenoh_shows_in_the_table_and_the_trend_within_a_second(
    page: Page,
) -> None:
    async with demo_daemon() as demo:
        await open_page(page, demo.url, len(DEMO_DRIVES))
        await page.wait_for_function(
            "Number(document.querySelector('.trend[data-drive=\"cfw11\"]').dataset.points) > 0",
            timeout=WAIT_MS,
        )
        started = time.monotonic()
        await demo.command("cfw11", {"run": True, "speed_rpm": 900})
        await page.wait_for_function(
            """() => {
                const row = document.querySelector('#drives-body tr[data-drive="cfw11"]');
                const ref = parseFloat(row.querySelector('td[data-col="ref"]').textContent);
                return ref > 890 && row.dataset.status !== 'ready';
            }""",
            timeout=WAIT_MS,
        )
        in_table = time.monotonic() - started
        await page.wait_for_function(
            "Number(document.querySelector('.trend[data-drive=\"cfw11\"]').dataset.lastRef) > 890",
            timeout=WAIT_MS,
        )
        in_trend = time.monotonic() - started
        await screenshot(page, "demo-cfw11-running")
        keep(
            f"command over Zenoh shown in the table after {in_table:.3f} s, in the trend after {in_trend:.3f} s\n"
        )
        assert in_table < SHOWN_WITHIN, f"the table showed it after {in_table:.2f} s"
        assert in_trend < SHOWN_WITHIN, f"the trend showed it after {in_trend:.2f} s"


async def test_a_drive_that_goes_offline_is_shown_offline(page: Page) -> None:
    async with demo_daemon() as demo:
        await open_page(page, demo.url, len(DEMO_DRIVES))
        sim = sim_runner(demo.adapter("devicenet"))
        assert sim is not None
        await demo.on_line("devicenet", lambda: sim.power_off(5))  # the demo's CFW-08, MAC 5
        await demo.wait_for("cfw08", lambda s: s.comm is CommState.OFFLINE)
        await page.wait_for_selector(
            '#drives-body tr[data-drive="cfw08"][data-comm="offline"]', timeout=WAIT_MS
        )
        await page.wait_for_selector(
            '#buses .station[data-drive="cfw08"][data-comm="offline"]', timeout=WAIT_MS
        )
        badge = page.locator('#drives-body tr[data-drive="cfw08"] td[data-col="comm"]')
        assert await badge.text_content() == "offline"
        await screenshot(page, "demo-cfw08-offline")
        sim.power_on(5)


async def test_with_commands_off_the_page_offers_no_command(page: Page) -> None:
    async with demo_daemon() as demo:
        await open_page(page, demo.url, len(DEMO_DRIVES))
        for selector in ("button", "input", "form", "[data-cmd]", 'td[data-col="commands"]'):
            assert await page.locator(selector).count() == 0, selector
        assert await page.locator("#command-bar").is_hidden()
        headers = await page.eval_on_selector_all(
            "#drives-head th", "ths => ths.map(t => t.textContent)"
        )
        assert "command" not in headers


HOSTILE_ID = '<img src=x onerror="window.pwned=1">'
HOSTILE_TEXT = '<script>window.pwned=2</script><b>bold</b> & "quoted"'


async def test_the_page_escapes_every_string_it_shows(page: Page) -> None:
    async with small_gateway(web_section(), drives=(HOSTILE_ID, "d2")) as gw:
        gw.hub.update(HOSTILE_ID, status=DriveStatus.FAULTED, fault_code=7, fault_text=HOSTILE_TEXT)
        await open_page(page, gw.url, 2)
        assert await rows(page) == [HOSTILE_ID, "d2"]
        row = page.locator("#drives-body tr").first
        assert await row.locator('td[data-col="id"]').text_content() == HOSTILE_ID
        assert await row.locator('td[data-col="fault"]').text_content() == f"7: {HOSTILE_TEXT}"
        await page.wait_for_function(
            "document.querySelector('#events').textContent.includes('window.pwned=2')",
            timeout=WAIT_MS,
        )
        await asyncio.sleep(PUSH_PERIOD * 4)  # a few pushes more, each one rendered
        assert await page.evaluate("window.pwned") is None
        assert await page.locator("main img, main b, main script").count() == 0
        await screenshot(page, "escaped")


async def test_with_commands_on_a_user_with_the_token_commands_from_the_page(page: Page) -> None:
    section = web_section(commands=True, token_sha256=TOKEN_SHA256)
    async with small_gateway(section) as gw:
        await open_page(page, gw.url, 2)
        run = page.locator('#drives-body tr[data-drive="d1"] button[data-cmd="run"]')
        await run.click()  # no token yet
        await page.wait_for_function(
            "document.querySelector('#command-result').textContent.includes('refused')",
            timeout=WAIT_MS,
        )
        assert not gw.hub.desired("d1").run
        await page.fill("#token", TOKEN)
        await run.click()
        await page.wait_for_function(
            "document.querySelector('#command-result').textContent.includes('accepted')",
            timeout=WAIT_MS,
        )
        desired = gw.hub.desired("d1")
        assert desired.run and desired.source is Source.WEB
        await page.wait_for_function(  # the page shows who is in control: itself
            'document.querySelector(\'#drives-body tr[data-drive="d1"] td[data-col="control"]\')'
            ".textContent.startsWith('web 127.0.0.1 ')",
            timeout=WAIT_MS,
        )
        await screenshot(page, "commands-on")


async def test_local_control_no_failsafe_and_doubtful_show_beside_the_status(page: Page) -> None:
    """Issue 32 items 5, 6, 12: what limits the gateway's command of a drive is on the page."""
    async with small_gateway(web_section(), drives=("d1", "d2")) as gw:
        await open_page(page, gw.url, 2)
        gw.hub.update("d1", local_control=True, failsafe=False, failsafe_text="P0313 = 0")
        gw.hub.update("d2", doubtful=True)
        status = '#drives-body tr[data-drive="{}"] td[data-col="status"] [data-safety="{}"]'
        for drive, kind in (("d1", "local"), ("d1", "no-failsafe"), ("d2", "doubtful")):
            await page.wait_for_selector(status.format(drive, kind), timeout=WAIT_MS)
        title = await page.locator(status.format("d1", "no-failsafe")).get_attribute("title")
        assert title is not None and "P0313 = 0" in title
        assert await page.locator(status.format("d2", "local")).count() == 0
        await screenshot(page, "safety-badges")


async def test_the_header_counts_faulted_drives_and_a_canopen_code_is_hex(page: Page) -> None:
    async with small_gateway(web_section(), drives=("d1", "d2", "d3")) as gw:
        gw.hub.add_drive(DriveState(id="co", device=Device.CIA402, bus="can", address=5))
        gw.hub.update("co", comm=CommState.ONLINE, status=DriveStatus.FAULTED, fault_code=0x8130)
        gw.hub.update("d3", comm=CommState.OFFLINE)
        await open_page(page, gw.url, 4)
        await page.wait_for_function(
            "document.querySelector('#summary').textContent"
            ".startsWith('4 drives: 2 ok, 1 faulted, 1 offline')",
            timeout=WAIT_MS,
        )
        fault = page.locator('#drives-body tr[data-drive="co"] td[data-col="fault"]')
        assert await fault.text_content() == "0x8130"
        gw.hub.update("d2", status=DriveStatus.TRIPPED, fault_code=26)  # a later update
        await page.wait_for_function(
            "document.querySelector('#summary').textContent"
            ".startsWith('4 drives: 1 ok, 2 faulted, 1 offline')",
            timeout=WAIT_MS,
        )
        row = page.locator('#drives-body tr[data-drive="d2"] td[data-col="fault"]')
        assert await row.text_content() == "26"
        await screenshot(page, "counts")


LOGIN_PASSWORD = "a good password"


def login_users() -> tuple[User, ...]:
    digest = hash_password(LOGIN_PASSWORD, n=1 << 14)
    return (User("vic", Role.VIEWER, digest), User("ana", Role.OPERATOR, digest))


async def log_in(page: Page, user: str, password: str) -> None:
    await page.fill("#login-user", user)
    await page.fill("#login-password", password)
    await page.click("#login-button")


async def test_a_login_gives_the_page_its_role_and_a_refusal_shows_why(page: Page) -> None:
    async with small_gateway(web_section(commands=True), users=login_users()) as gw:
        await open_page(page, gw.url, 2)
        await log_in(page, "vic", LOGIN_PASSWORD)
        await page.wait_for_function(
            "(document.querySelector('#who') || {}).textContent === 'vic (viewer)'",
            timeout=WAIT_MS,
        )
        run = page.locator('#drives-body tr[data-drive="d1"] button[data-cmd="run"]')
        await run.click()
        await page.wait_for_function(
            "document.querySelector('#command-result').textContent.includes("
            "'refused: vic has the viewer role; command needs operator or above')",
            timeout=WAIT_MS,
        )
        assert not gw.hub.desired("d1").run
        await screenshot(page, "login-viewer-refused")
        await page.click("#logout")
        await log_in(page, "ana", "not the password")
        await page.wait_for_function(
            "document.querySelector('#login-result').textContent.includes('wrong user name')",
            timeout=WAIT_MS,
        )
        await log_in(page, "ana", LOGIN_PASSWORD)
        await page.wait_for_function(
            "(document.querySelector('#who') || {}).textContent === 'ana (operator)'",
            timeout=WAIT_MS,
        )
        assert await page.evaluate("document.cookie") == ""  # HttpOnly: no script reads it
        await run.click()
        await page.wait_for_function(
            "document.querySelector('#command-result').textContent.includes('accepted')",
            timeout=WAIT_MS,
        )
        assert gw.hub.desired("d1").run
        await screenshot(page, "login-operator")
    seen = [(r["type"], r["result"], r["identity"]) for r in gw.runtime.audit.newest()]
    assert seen == [
        ("login", "success", "vic"),
        ("refused", "failure", "vic"),
        ("logout", "success", "vic"),
        ("login", "failure", "ana"),
        ("login", "success", "ana"),
        ("command", "success", "ana"),
    ]


async def test_with_anonymous_none_the_page_asks_for_a_login_first(page: Page) -> None:
    async with small_gateway(web_section(anonymous=False), users=login_users()) as gw:
        await page.goto(gw.url)
        await page.wait_for_selector("#login-user", timeout=WAIT_MS)
        assert await rows(page) == []  # nothing shown before the login
        await log_in(page, "vic", LOGIN_PASSWORD)
        await page.wait_for_function(  # the page opens its feed with the session
            "document.querySelectorAll('#drives-body tr').length === 2", timeout=WAIT_MS
        )
        assert await page.locator("#command-bar").is_hidden()  # a viewer, commands off
        await screenshot(page, "login-first")
