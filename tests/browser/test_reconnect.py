"""The page survives the service going away: it shows that it is reconnecting, then resyncs from a snapshot."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from browser_kit import Dashboard, LinkCutter, Service, parse_map_csv

pytestmark = pytest.mark.browser


def refused(text: str) -> bool:
    """What Chromium itself logs while nothing listens on the port (not the page's own errors)."""
    return "ERR_CONNECTION_REFUSED" in text or ("WebSocket connection to" in text and "failed" in text)


def cut_off(text: str) -> bool:
    """What Chromium logs if a plain HTTP request was in flight when the link was cut."""
    return any(e in text for e in ("ERR_CONNECTION_RESET", "ERR_EMPTY_RESPONSE", "ERR_CONNECTION_CLOSED"))


@pytest.fixture
def link(service: Service) -> Iterator[LinkCutter]:
    cutter = LinkCutter(service.port)
    try:
        yield cutter
    finally:
        cutter.close()


def test_page_resyncs_after_its_connection_drops(
    dashboard: Dashboard, service: Service, link: LinkCutter, expect: Any
) -> None:
    page = dashboard.page
    dashboard.open(base_url=link.url)
    run_id = dashboard.start_run("room2", speed="10")
    dashboard.wait_state("s => s.steps >= 2", 30)
    before = dashboard.state()

    dashboard.console.allow.append(cut_off)
    link.hold()
    link.cut()
    expect(page.locator("#conn")).to_have_attribute("data-state", "reconnecting")
    expect(page.locator("#conn")).to_contain_text("Reconnecting")
    link.release()

    # Same service, same session: the page carries on from a fresh snapshot, and steps flow again.
    dashboard.wait_state(f"s => s.connection === 'live' && s.snapshots > {before['snapshots']}")
    seq = dashboard.state()["seq"]
    dashboard.wait_state(f"s => s.seq > {seq}", 30)
    dashboard.console.allow.clear()
    after = dashboard.state()
    assert after["session"] == before["session"]
    assert after["restarts"] == 0
    assert after["reconnects"] >= 1

    page.get_by_role("button", name="Stop run").click()
    dashboard.wait_state("s => s.connection === 'ended'", 30)
    expected = parse_map_csv(service.api("GET", f"/api/runs/{run_id}/map.csv").text)
    assert page.evaluate("window.sonarslam.cells()") == expected
    dashboard.assert_no_console_errors()


def test_page_recovers_after_the_service_crashes_and_restarts(
    dashboard: Dashboard, service: Service, expect: Any
) -> None:
    page = dashboard.page
    dashboard.open()
    run_id = dashboard.start_run("room2", speed="5")  # slow enough to still be running when the service dies
    dashboard.wait_state("s => s.steps >= 3", 30)
    before = dashboard.state()
    assert before["connection"] == "live"

    dashboard.console.allow.append(refused)
    service.stop(crash=True)  # SIGKILL: the socket drops without a closing status
    expect(page.locator("#conn")).to_have_attribute("data-state", "reconnecting")
    expect(page.locator("#conn")).to_contain_text("Reconnecting")
    service.start()

    # The new service has a new session: the page starts over from its snapshot. The run was cut
    # short by the crash, so the service reports it interrupted with its last checkpoint.
    dashboard.wait_state(
        f"s => s.session !== {before['session']!r} && s.connection === 'ended'",
        30,
    )
    after = dashboard.state()
    assert after["restarts"] == 1
    assert after["reconnects"] >= 1
    assert after["snapshots"] == before["snapshots"] + 1
    assert after["status"] == "interrupted"
    expect(page.locator("#stat-status")).to_have_text("interrupted")
    expected = parse_map_csv(service.api("GET", f"/api/runs/{run_id}/map.csv").text)
    assert page.evaluate("window.sonarslam.cells()") == expected
    dashboard.console.allow.clear()
    dashboard.assert_no_console_errors()
