"""The status page at / in a real headless browser (Debian's chromium, driven by Playwright):
it loads with no internet, shows every drive in a row of its overview and the counts per
line, opens a drive's detail on demand (its values, alarms, settings, write form), and
follows their changes, fetching only what it shows.

.ci/run installs chromium (deploy/browser-setup); without it, or without Playwright,
the test is skipped with the reason.
"""

from __future__ import annotations

import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import httpx
import pytest

from tests.service.http.conftest import AUTH, TOKEN, service
from tests.service.http.threaded import ServedInThread, served_in_thread

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run",
]  # fmt: skip
DRIVES = [
    {"name": "fan1", "address": 1, "catalog": "danfoss-fc",
     "poll": [("3-41", "100ms"), ("16-13", "200ms"), ("16-90", "200ms"), ("0-01", "1s")],
     "writable": ["3-41", "0-01"]},
    {"name": "fan2", "address": 2, "catalog": "danfoss-fc",
     "poll": [("3-41", "100ms"), ("16-90", "200ms")], "writable": []},
    # Nothing polled, not even the counters polled by default.
    {"name": "fan3", "address": 3, "catalog": "danfoss-fc", "poll": [], "writable": [],
     "counters": "off"},
]  # fmt: skip


@pytest.fixture
def served(tmp_path: Path) -> Iterator[ServedInThread]:
    with served_in_thread(tmp_path, TOKEN, fc=DRIVES) as running:
        yield running


def fetched_only_what_it_shows(asked: list[tuple[str, str]]) -> None:
    """The page's reads of the drives: the overview's rows (after the first answer, only
    those changed since) and the one drive whose detail is open; trends of that drive."""
    reads = [urlsplit(url) for method, url in asked if method == "GET"]
    drives = [parse_qs(u.query) for u in reads if u.path.endswith("/api/v1/drives")]
    assert drives, asked
    for query in drives:
        assert query.get("view") == ["overview"] or "drive" in query, query
    overview = [q for q in drives if q.get("view") == ["overview"]]
    assert "changed_since" not in overview[0], overview[0]
    assert any("changed_since" in q for q in overview), overview
    assert any("changed_since" in q for q in drives if "drive" in q), drives
    trends = [parse_qs(u.query) for u in reads if u.path.endswith("/api/v1/trends")]
    assert trends and all("drive" in q for q in trends), trends


def test_status_page_in_a_browser(served: ServedInThread, tmp_path: Path) -> None:
    sync_api = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no chromium at {CHROMIUM} (deploy/browser-setup installs it)")
    expect = sync_api.expect
    elsewhere: list[str] = []
    asked: list[tuple[str, str]] = []  # the page's requests: method, URL
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})

            def only_here(route: Any) -> None:  # no internet: anything else is refused
                if route.request.url.startswith(served.url):
                    route.continue_()
                else:
                    elsewhere.append(route.request.url)
                    route.abort()

            page.route("**/*", only_here)
            page.on("request", lambda r: asked.append((r.method, r.url)))
            # A quarter of an hour of trend behind two values (the sparklines' points).
            served.history("fan1", "16-13", [30.0 + (k % 12) for k in range(59)])
            served.history("fan2", "3-41", [5.0 + (k // 20) for k in range(59)])
            page.goto(served.url + "/")

            # The overview: a row per drive, its state, the age of its newest value.
            def row(name: str) -> Any:
                return page.locator(f'#drives tbody tr[data-drive="{name}"]')

            def order() -> list[str]:
                return list(page.locator("#drives tbody tr").evaluate_all(
                    "rows => rows.filter(r => !r.hidden).map(r => r.dataset.drive)"
                ))  # fmt: skip

            expect(page.locator("#drives tbody tr")).to_have_count(3, timeout=20_000)
            expect(row("fan1").locator(".state")).to_have_text("up")
            expect(row("fan1").locator(".address")).to_have_text("1")
            expect(row("fan1").locator(".age")).to_have_text(re.compile(r"^\d+ s$"), timeout=20_000)
            expect(row("fan1").locator(".faults")).to_have_text("0")
            expect(row("fan3").locator(".age")).to_have_text("none yet")
            expect(page.locator("#shown-count")).to_have_text("(3)")
            # Its bus as the API names it; its settings not swept: no count.
            expect(row("fan1").locator(".bus")).to_have_text("FC")
            expect(row("fan1").locator(".settings")).to_have_text("-")
            # The counts per line: the port, the drives up, down, ...; busy from the second
            # refresh on; and all lines together.
            line = page.locator('#lines [data-line="line_fc"]')
            expect(line).to_contain_text("open")
            expect(line.locator(".drives")).to_have_text("3")
            expect(line.locator(".up")).to_have_text("3")
            expect(line.locator(".down")).to_have_text("0")
            busy = line.locator(".busy")
            expect(busy).to_have_text(re.compile(r"^\d+ %$"), timeout=20_000)
            expect(page.locator("#lines tfoot")).to_contain_text("1 of 1 open")

            # Filtered and sorted in the page.
            page.fill("#filter-text", "FAN2")
            expect(row("fan1")).to_be_hidden()
            expect(row("fan2")).to_be_visible()
            expect(page.locator("#shown-count")).to_have_text("(1 of 3 shown)")
            assert "find=FAN2" in page.url
            page.fill("#filter-text", "")
            page.select_option("#filter-state", "down")
            expect(page.locator("#no-match")).to_be_visible()
            page.select_option("#filter-state", "settings")  # none swept: none changed
            expect(page.locator("#no-match")).to_be_visible()
            page.select_option("#filter-state", "")
            expect(page.locator("#no-match")).to_be_hidden()
            # A PROFIBUS DP slave out of data exchange (the answers made so): its state in
            # the live list beside its bus, in red, and found by it.
            overview = re.compile(r".*/api/v1/drives\?view=overview.*")

            def on_dp(route: Any) -> None:
                response = route.fetch()
                rows = response.json()
                for r in rows:
                    if r["name"] == "fan3":
                        r["protocol"], r["dp_state"] = "profibus", "wait_prm"
                route.fulfill(response=response, json=rows)

            def at_a_full_refresh(cell: Any, text: str) -> None:
                """Every row asked for at the next refresh until ``cell`` shows ``text`` (fan3
                polls nothing: its row is in no answer of the rows changed; an answer under
                way may be of before the change)."""
                deadline = time.monotonic() + 30
                while True:
                    page.evaluate("fullAt = 0")
                    try:
                        expect(cell).to_have_text(text, timeout=3_000)
                        return
                    except AssertionError:
                        assert time.monotonic() < deadline, f"{text!r} not shown"

            page.route(overview, on_dp)
            bus = row("fan3").locator(".bus")
            at_a_full_refresh(bus, "DP wait prm")
            expect(bus).to_have_class(re.compile(r"\bbad\b"))
            expect(bus).to_have_attribute("title", re.compile(r"^PROFIBUS DP: wait prm"))
            page.fill("#filter-text", "wait prm")
            expect(page.locator("#shown-count")).to_have_text("(1 of 3 shown)")
            page.fill("#filter-text", "")
            page.unroute(overview, on_dp)
            at_a_full_refresh(bus, "FC")
            page.click('#drives th button[data-sort="name"]')
            assert order() == ["fan1", "fan2", "fan3"]
            expect(page.locator("#drives th", has_text="drive")).to_have_attribute(
                "aria-sort", "ascending"
            )
            page.click('#drives th button[data-sort="name"]')
            assert order() == ["fan3", "fan2", "fan1"]
            page.click('#drives th button[data-sort="state"]')  # the default: urgent first

            # A drive's detail, opened by a click on its row.
            row("fan1").click()
            detail = page.locator("#detail")
            expect(detail).to_have_attribute("data-drive", "fan1")
            expect(row("fan1")).to_have_class(re.compile(r"\bopen\b"))
            assert "drive=fan1" in page.url
            fan1 = page.locator('#detail[data-drive="fan1"]')
            ramp = fan1.locator('[data-parameter="3-41"] .value')
            expect(ramp).to_have_text(re.compile(r"^\d+(\.\d+)? s$"), timeout=20_000)
            expect(fan1.locator(".state")).to_have_text("up")
            # Its settings are not swept: nothing shown of them.
            expect(fan1.locator(".settings")).to_be_hidden()
            # to the resolution of its conversion index (-1), with the catalog's name
            frequency = fan1.locator('[data-parameter="16-13"]')
            expect(frequency.locator(".value")).to_have_text(re.compile(r"^\d+\.\d Hz$"))
            expect(frequency.locator(".title")).to_have_text("Frequency")
            # Stale only after twice its poll interval, at least the interval and 10 s.
            expect(frequency.locator(".age")).to_have_attribute(
                "title", "polled every 200 ms: stale after 10 s"
            )
            expect(frequency).not_to_have_class("stale")
            stale = page.evaluate("[60, 0.2, 1, null].map(staleAfter)")
            assert stale == [120, 10.2, 11, 30], stale
            # Its sparkline: a line through the points of the last 15 minutes.
            spark = frequency.locator(".trend svg.spark")
            expect(spark).to_have_count(1)
            expect(spark.locator("title")).to_have_text(
                re.compile(r"^last 15 min: 30 to \d+(\.\d+)?$"), timeout=20_000
            )
            drawn = spark.locator("path").get_attribute("d") or ""
            assert drawn.startswith("M") and drawn.count("L") >= 50, drawn
            # New trends redraw a kept row's sparkline in its place (asked for now rather
            # than at the page's next 15 s).
            ramp_spark = fan1.locator('[data-parameter="3-41"] .trend svg.spark')
            served.history("fan1", "3-41", [2.0 + (k % 3) for k in range(59)])
            page.evaluate("trendsFetched = 0")
            expect(ramp_spark.locator("title")).to_have_text(
                re.compile(r"^last 15 min: 2 to \d+(\.\d+)?$"), timeout=20_000
            )
            # An enumeration: the option's text as the Danfoss design guide words it.
            language = fan1.locator('[data-parameter="0-01"]')
            expect(language.locator(".value")).to_have_text("English [0]")
            expect(language.locator(".title")).to_have_text("Language")
            expect(fan1.locator(".bits")).to_contain_text("running")
            expect(fan1.locator(".counts")).to_contain_text("faults")

            # Kept across refreshes and changes: the same row, the same cell, filled in place.
            nodes = """[document.querySelector('#drives tr[data-drive="fan1"]'),
                document.querySelector('#detail [data-parameter="3-41"] .value')]"""
            page.evaluate(f"window.kept = {nodes}")
            served.set_value(1, 341, 4321)  # the drive changes: the page follows by itself
            expect(ramp).to_have_text("43.21 s", timeout=20_000)
            same = page.evaluate(f"{nodes}.every((node, i) => node === window.kept[i])")
            assert same, "the row or the value was drawn anew"

            # A trip: its alarm in the vendor's words (16-90 bit 2, Danfoss MCA 121 manual)
            # in its row, which comes first, and counted on its line.
            served.trip(2, 14, 2)
            expect(row("fan2").locator(".alarms")).to_contain_text("Earth fault", timeout=20_000)
            expect(row("fan2")).to_have_class(re.compile(r"\balarm\b"))
            assert order()[0] == "fan2"
            expect(line.locator(".alarm")).to_have_text("1")
            line.locator(".alarm button").click()  # the count shows those drives
            expect(row("fan1")).to_be_hidden()
            assert order() == ["fan2"]
            page.click("#filter-reset")
            expect(row("fan1")).to_be_visible()
            # Its detail: the alarm with its code, in red.
            row("fan2").click()
            expect(detail).to_have_attribute("data-drive", "fan2")
            expect(row("fan1")).not_to_have_class(re.compile(r"\bopen\b"))
            fan2 = page.locator('#detail[data-drive="fan2"]')
            alarm = fan2.locator('ul.alarms li[data-code="16-90 bit 2"]')
            expect(alarm).to_contain_text("Earth fault", timeout=20_000)
            expect(alarm).to_have_class("alarm")
            expect(page.locator("#write-none")).to_be_visible()  # nothing writable on fan2
            expect(page.locator("#write-form")).to_be_hidden()
            # A drive in maintenance: shown so, with its reason, neither up nor down.
            url = served.url + "/api/v1/drives/fan2/maintenance"
            held = httpx.put(url, json={"on": True, "reason": "bearing change"}, headers=AUTH)
            assert held.status_code == 200, held.text
            expect(fan2.locator(".state")).to_have_text("maintenance", timeout=20_000)
            expect(fan2.locator("p.maintenance")).to_contain_text("bearing change")
            expect(row("fan2").locator(".state")).to_have_text("maintenance", timeout=20_000)
            expect(line.locator(".maintenance")).to_have_text("1")
            assert httpx.put(url, json={"on": False}, headers=AUTH).status_code == 200
            expect(fan2.locator(".state")).to_have_text("up", timeout=20_000)
            expect(fan2.locator("p.maintenance")).to_have_count(0)
            expect(row("fan2").locator(".state")).to_have_text("up", timeout=20_000)

            # A drive with nothing polled says so.
            row("fan3").click()
            fan3 = page.locator('#detail[data-drive="fan3"]')
            expect(fan3.locator("p.nothing")).to_have_text("Nothing is polled on this drive.")
            expect(fan3.locator("table.values")).to_have_count(0)
            # A drive none of whose values was read yet (as just after the start) says
            # that, not that nothing is polled: its answer given so, the rest as it is.
            fan1_answer = re.compile(r".*/api/v1/drives\?drive=fan1(&.*)?$")

            def unread(route: Any) -> None:
                response = route.fetch()
                views = response.json()
                for view in views:
                    view["values"] = []
                route.fulfill(response=response, json=views)

            page.route(fan1_answer, unread)
            row("fan1").click()
            expect(fan1.locator("p.nothing")).to_have_text(
                re.compile(r"None of the \d+ values polled has been read yet\.")
            )
            page.unroute(fan1_answer, unread)
            # Closed, and opened again from the address.
            page.click("#detail-close")
            expect(detail).to_be_hidden()
            assert "drive=" not in page.url
            page.evaluate("location.hash = '#drive=fan1'")
            expect(fan1.locator('[data-parameter="3-41"] .value')).to_have_text(
                "43.21 s", timeout=20_000
            )

            # The last write attempts show once the page is given a token.
            audit = page.locator("#audit")
            expect(audit).to_be_hidden()
            written = httpx.put(
                f"{served.url}/api/v1/drives/fan1/parameters/3-41",
                json={"value": 7.5}, headers=AUTH, timeout=30,
            )  # fmt: skip
            assert written.status_code == 200, written.text
            page.fill("#token", TOKEN)
            page.click("#token-form button")
            expect(audit).to_contain_text("fan1", timeout=20_000)
            expect(audit).to_contain_text("7.5")
            expect(audit.locator("tbody tr").first).to_contain_text("ok")
            assert page.input_value("#token") == ""  # not left in the form

            # An enumeration's form lists its options with their texts.
            page.select_option("#write-target", "fan1/0-01")
            expect(page.locator("#write-now")).to_contain_text(
                "Language: now English [0]; options 0 English, 4 Danish"
            )
            # The write form: the parameter, its limits and value, a confirmation, the answer.
            page.select_option("#write-target", "fan1/3-41")
            expect(page.locator("#write-now")).to_contain_text("now 7.5 s")
            page.fill("#write-value", "12.5")
            page.click("#write-button")
            expect(page.locator("#write-button")).to_have_text(
                re.compile(r"^Confirm: 7\.5 \u2192 12\.5 s$")
            )
            assert served.svc.sim.drives[1].value(341) == 750  # nothing sent before the confirm
            page.click("#write-button")
            result = page.locator("#write-result")
            expect(result).to_contain_text("fan1/3-41: written 12.5 s", timeout=20_000)
            assert served.svc.sim.drives[1].value(341) == 1250
            expect(audit.locator("tbody tr").first).to_contain_text("12.5", timeout=20_000)
            # A value outside the limits: the API's refusal, in words, and nothing sent.
            page.fill("#write-value", "99999")
            page.click("#write-button")
            page.click("#write-button")
            expect(result).to_contain_text("refused (422", timeout=20_000)
            assert served.svc.sim.drives[1].value(341) == 1250
            # A wrong token: refused.
            page.fill("#token", "not-the-token")
            page.click("#token-form button")
            expect(result).to_contain_text("token: the token was refused", timeout=20_000)
            expect(page.locator("#token-note")).to_have_text("the token was refused")
            page.fill("#write-value", "10")
            page.click("#write-button")
            expect(result).to_contain_text("type the write token below first")
            expect(ramp).to_have_text("12.50 s", timeout=20_000)  # what the drive holds
            page.fill("#write-value", "")
            # The right token again; another parameter chosen: the last answer goes.
            page.fill("#token", TOKEN)
            page.click("#token-form button")
            expect(page.locator("#token-note")).to_have_text("")
            expect(audit).to_be_visible(timeout=20_000)
            page.select_option("#write-target", "fan1/0-01")
            expect(result).to_be_hidden()
            page.evaluate("window.scrollTo(0, 0)")  # its sticky heads where they belong

            shot = tmp_path / "status-page.png"
            page.screenshot(path=str(shot), full_page=True)
            print(f"\nstatus page screenshot: {shot}")
            wanted = os.environ.get("PKWBUS_STATUS_SCREENSHOT")  # make status-page
            if wanted:
                shutil.copyfile(shot, wanted)
                print(f"copied to {wanted}")
        finally:
            browser.close()
    assert elsewhere == []
    fetched_only_what_it_shows(asked)


def test_status_page_at_plant_scale_draws_the_rows_near_the_screen(served: ServedInThread) -> None:
    """1,008 drives (the overview's answers made so): the rows near the screen are drawn,
    and every drive is found by the filter, the sort and the scroll bar; a printout draws
    every row."""
    sync_api = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no chromium at {CHROMIUM} (deploy/browser-setup installs it)")
    expect = sync_api.expect
    now = time.time()
    rows = [
        {"name": f"l{n}d{d}", "line": f"l{n}", "protocol": "fc", "address": d, "state": "up",
         "dp_state": None, "faults": 0, "telegram_errors": 0, "alarms": [], "warnings": [],
         "updated": now, "age": 0.0, "settings_changed": None}
        for n in range(8) for d in range(1, 127)
    ]  # fmt: skip
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.route(re.compile(r".*/api/v1/drives\?view=overview.*"),
                       lambda route: route.fulfill(json=rows))  # fmt: skip
            page.goto(served.url + "/")
            table = page.locator("#drives")
            drawn = page.locator("#drives tbody tr")
            expect(table).to_have_attribute("aria-rowcount", "1009", timeout=20_000)
            expect(page.locator("#shown-count")).to_have_text("(1008)")
            expect(page.locator("#lines tfoot td.drives")).to_have_text("1008")
            count = drawn.count()
            assert 0 < count < 200, f"{count} rows drawn of 1,008"
            expect(drawn.first).to_have_attribute("aria-rowindex", "2")
            # Any drive found by the filter.
            page.fill("#filter-text", "l7d126")
            expect(drawn).to_have_count(1)
            expect(drawn.first).to_have_attribute("data-drive", "l7d126")
            expect(page.locator("#shown-count")).to_have_text("(1 of 1008 shown)")
            page.fill("#filter-text", "")
            expect(table).to_have_attribute("aria-rowcount", "1009")
            # By the sort: the last by name first.
            page.click('#drives th button[data-sort="name"]')
            page.click('#drives th button[data-sort="name"]')
            expect(drawn.first).to_have_attribute("data-drive", "l7d126")
            # By the scroll bar: the last row drawn at the end of the table.
            page.evaluate("window.scrollTo(0, document.body.scrollHeight)")
            last = page.locator('#drives tbody tr[data-drive="l0d1"]')
            expect(last).to_be_in_viewport()
            expect(last).to_have_attribute("aria-rowindex", "1009")
            expect(last.locator(".age")).to_have_text(re.compile(r"^\d+ s$"))
            assert drawn.count() < 200
            # A printout: every row.
            page.evaluate("window.dispatchEvent(new Event('beforeprint'))")
            expect(drawn).to_have_count(1008)
            page.evaluate("window.dispatchEvent(new Event('afterprint'))")
            expect(drawn).not_to_have_count(1008)
        finally:
            browser.close()


# Two drives whose 3-41 and 3-42 are swept every second (the line's settings).
SWEPT = [
    {"name": name, "address": address, "catalog": "danfoss-fc",
     "poll": [("16-13", "200ms")], "writable": []}
    for name, address in (("fan1", 1), ("fan2", 2))
]  # fmt: skip
SETTINGS = '{every: 1s, parameters: ["3-41", "3-42"]}'


def js_number(value: float) -> str:
    """A number as the page's script writes it (10.0 as 10)."""
    return f"{value:g}"


def test_status_page_shows_the_settings_changed_from_their_baseline(tmp_path: Path) -> None:
    sync_api = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no chromium at {CHROMIUM} (deploy/browser-setup installs it)")
    with served_in_thread(tmp_path, TOKEN, fc=SWEPT, settings=SETTINGS) as served:

        def settings(drive: str) -> dict[str, Any]:
            r = httpx.get(f"{served.url}/api/v1/drives/{drive}/settings", timeout=30)
            assert r.status_code == 200, r.text
            return dict(r.json())

        def ramp(drive: str) -> dict[str, Any]:
            return next(p for p in settings(drive)["parameters"] if p["parameter"] == "3-41")

        def until(check: Any, what: str) -> None:
            deadline = time.monotonic() + 30
            while not check():
                assert time.monotonic() < deadline, what
                time.sleep(0.1)

        # Each drive's first complete sweep is its baseline.
        until(lambda: all(settings(d)["swept"] for d in ("fan1", "fan2")), "no complete sweep")
        elsewhere: list[str] = []
        asked: list[str] = []  # the page's requests of the settings
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            try:
                page = browser.new_page(viewport={"width": 1100, "height": 800})

                def only_here(route: Any) -> None:
                    if route.request.url.startswith(served.url):
                        route.continue_()
                    else:
                        elsewhere.append(route.request.url)
                        route.abort()

                page.route("**/*", only_here)
                page.on("request", lambda r: asked.append(r.url) if "/settings" in r.url else None)
                page.goto(served.url + "/")
                # Asked for when its detail opens.
                page.locator('#drives tr[data-drive="fan1"]').click()
                fan1 = page.locator('#detail[data-drive="fan1"]')
                sweep = fan1.locator(".settings p.sweep")
                sync_api.expect(sweep).to_contain_text(
                    "none of 2 settings differs from the baseline", timeout=20_000
                )
                sync_api.expect(sweep).to_contain_text(
                    re.compile(r"last complete sweep .+ \(\d+ s ago\), every 1 s")
                )
                sync_api.expect(fan1.locator("table.changed")).to_have_count(0)

                # A change at fan2's keypad, found by its next sweep.
                before = ramp("fan2")
                served.keypad(2, 341, before["raw"] + 150)
                until(lambda: ramp("fan2")["changed"], "the keypad change was not found")
                changed = ramp("fan2")
                page.locator('#drives tr[data-drive="fan2"]').click()
                fan2 = page.locator('#detail[data-drive="fan2"]')
                row = fan2.locator('table.changed tr[data-parameter="3-41"]')
                sync_api.expect(row).to_be_visible(timeout=20_000)
                # Not asked for at every 2 s refresh: again after 30 s.
                count = len(asked)
                page.wait_for_timeout(4500)
                assert len(asked) == count, asked[count:]
                page.evaluate("settingsAt = 0")  # the next one now rather than in 30 s
                sync_api.expect(row).to_be_visible(timeout=20_000)
                sync_api.expect(row.locator(".title")).to_have_text(changed["name"])
                sync_api.expect(row.locator(".value")).to_have_text(
                    f"{js_number(changed['value'])} s"
                )
                sync_api.expect(row.locator(".baseline")).to_have_text(
                    f"{js_number(before['value'])} s"
                )
                sync_api.expect(row.locator(".baseline-since")).to_contain_text("(sweep)")
                sync_api.expect(row.locator(".since")).not_to_have_text("?")
                sync_api.expect(fan2.locator(".settings p.sweep .alarm")).to_have_text(
                    "1 of 2 settings differ from the baseline"
                )
                sync_api.expect(fan2.locator(".settings")).to_contain_text(
                    "PUT api/v1/drives/fan2/settings/baseline"
                )
                # Counted in its overview row, in red, and found by the state filter.
                counted = page.locator('#drives tr[data-drive="fan2"] td.settings')
                sync_api.expect(counted).to_have_text("1", timeout=20_000)
                sync_api.expect(counted).to_have_class(re.compile(r"\bbad\b"))
                sync_api.expect(page.locator('#drives tr[data-drive="fan1"] td.settings')
                                ).to_have_text("0")  # fmt: skip
                page.select_option("#filter-state", "settings")
                sync_api.expect(page.locator("#drives tbody tr")).to_have_count(1)
                sync_api.expect(page.locator('#drives tr[data-drive="fan2"]')).to_be_visible()
                page.select_option("#filter-state", "")
                # It stands out as an alarm does (asked again until it holds: a refresh
                # may replace the row between the look and the style's reading).
                sync_api.expect(row.locator(".value")).to_have_css("color", "rgb(176, 0, 32)")
                # Also an entry of the drives' logs, kind "setting".
                page.evaluate("eventsAt = 0")
                sync_api.expect(page.locator("#events")).to_contain_text("3-41", timeout=20_000)
                sync_api.expect(page.locator("#events")).to_contain_text("setting")
                # and of the open drive's own log
                page.evaluate("driveEventsAt = 0")
                mine = page.locator("#drive-events")
                sync_api.expect(mine).to_contain_text("3-41", timeout=20_000)
                sync_api.expect(mine).to_contain_text("setting")

                # Accepted as the baseline: nothing differs any more.
                url = f"{served.url}/api/v1/drives/fan2/settings/baseline"
                accepted = httpx.put(url, headers=AUTH, timeout=30)
                assert accepted.status_code == 200, accepted.text
                page.evaluate("settingsAt = 0")
                sync_api.expect(fan2.locator("table.changed")).to_have_count(0, timeout=20_000)
                sync_api.expect(fan2.locator(".settings p.sweep")).to_contain_text(
                    "none of 2 settings differs from the baseline"
                )
                sync_api.expect(counted).to_have_text("0", timeout=20_000)
            finally:
                browser.close()
        assert elsewhere == []
        # Relative to the page, like its other requests.
        assert asked and all(u.startswith(served.url + "/api/v1/drives/") for u in asked), asked


async def test_status_page_and_assets_are_served_locally(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        page = await svc.client.get("/")
        assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
        assets = re.findall(r"""(?:src|href)="([^"]+)""", page.text)
        assert {"assets/status/status.js", "assets/status/status.css"} <= set(assets)
        for asset in assets:
            # Relative to the page: from this host, under whatever prefix serves it.
            assert not asset.startswith("/") and "//" not in asset, asset
            assert (await svc.client.get("/" + asset)).status_code == 200, asset
        script = (await svc.client.get("/assets/status/status.js")).text
        # The SVG namespace is a name the browser never fetches; nothing else is a URL.
        script = script.replace('"http://www.w3.org/2000/svg"', '"svg-namespace"')
        assert "http://" not in script and "https://" not in script
        assert "`api/v1/drives?view=overview${since}`" in script
        assert "`api/v1/drives?drive=${encodeURIComponent(d.name)}${since}`" in script
        assert "`api/v1/trends?drive=${encodeURIComponent(d.name)}`" in script
        assert '"api/v1/trends"' not in script  # never every drive's trends
        assert "`api/v1/drives/${encodeURIComponent(name)}/settings`" in script
        assert not re.search(r"""["'`]/(api|readyz|metrics|docs|assets)""", script)
