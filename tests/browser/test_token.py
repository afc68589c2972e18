"""A service that requires a token: the page asks for it once, remembers it for the session, and uses it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from browser_kit import Dashboard, Service

pytestmark = pytest.mark.browser

TOKEN = "browser-test-token-1234"


def unauthorized(text: str) -> bool:
    """Chromium logs every 401 answer; here they are the expected prompt for a token."""
    return "status of 401" in text


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    """Viewing and control both need the token."""
    base = tmp_path_factory.mktemp("token-service")
    svc = Service(
        data_dir=base / "data",
        log_path=base / "service.log",
        extra_args=("--token", TOKEN),
        extra_env={"SONARSLAM_VIEW_ACCESS": "token"},
    )
    svc.start()
    try:
        yield svc
    finally:
        svc.stop()


def test_page_asks_for_the_token_and_keeps_it_for_the_session(
    dashboard: Dashboard, service: Service, expect: Any, tmp_path: Path
) -> None:
    page = dashboard.page
    dashboard.console.allow.append(unauthorized)
    page.goto(service.url + "/")
    dialog = page.get_by_role("dialog", name="Access token")
    expect(dialog).to_be_visible()
    page.get_by_label("Token", exact=True).fill(TOKEN)
    page.get_by_role("button", name="Continue").click()
    expect(dialog).to_be_hidden()
    page.wait_for_function("document.querySelector('#world option')")

    # Start, watch (the socket carries the token in its query) and stop a run.
    run_id = dashboard.start_run("room2", speed="20")
    dashboard.wait_state("s => s.connection === 'live' && s.steps > 0", 30)
    page.get_by_role("button", name="Stop run").click()
    dashboard.wait_state("s => s.connection === 'ended'", 30)
    assert dashboard.state()["status"] == "stopped"

    # Downloads need the token too: the link fetches with it.
    with page.expect_download() as info:
        page.get_by_role("link", name="Map CSV").click()
    saved = tmp_path / "map.csv"
    info.value.save_as(saved)
    headers = {"Authorization": f"Bearer {TOKEN}"}
    assert saved.read_text() == service.api("GET", f"/api/runs/{run_id}/map.csv", headers=headers).text

    # A reload in the same tab does not ask again; it reopens the run (its id is in the URL's
    # fragment), whose socket still gets the token.
    page.reload()
    page.wait_for_function("document.querySelector('#world option')")
    expect(dialog).to_be_hidden()
    state = dashboard.wait_state("s => s.connection === 'ended'")
    assert state["runId"] == run_id
    assert state["reconnects"] == 0
    dashboard.console.allow.clear()
    dashboard.assert_no_console_errors()


def test_token_in_the_page_url_is_used_and_removed_from_the_address(
    dashboard: Dashboard, service: Service, expect: Any
) -> None:
    headers = {"Authorization": f"Bearer {TOKEN}"}
    res = service.api("POST", "/api/runs", json={"world": "room2", "speed": "max"}, headers=headers)
    assert res.status_code == 201, res.text
    run_id = res.json()["id"]
    page = dashboard.page
    page.goto(f"{service.url}/?token={TOKEN}#run={run_id}")
    page.wait_for_function("document.querySelector('#world option')")
    expect(page.get_by_role("dialog", name="Access token")).to_be_hidden()
    assert "token" not in page.url
    state = dashboard.wait_state("s => s.snapshots > 0")
    assert state["runId"] == run_id
    assert state["reconnects"] == 0  # the socket carried the token from the start
    dashboard.assert_no_console_errors()


def test_a_wrong_token_is_asked_for_again(dashboard: Dashboard, service: Service, expect: Any) -> None:
    page = dashboard.page
    dashboard.console.allow.append(unauthorized)
    page.goto(f"{service.url}/?token=not-the-token")
    dialog = page.get_by_role("dialog", name="Access token")
    expect(dialog).to_be_visible()
    expect(dialog).to_contain_text("not accepted")
    page.get_by_label("Token", exact=True).fill(TOKEN)
    page.get_by_role("button", name="Continue").click()
    page.wait_for_function("document.querySelector('#world option')")
    expect(dialog).to_be_hidden()
    dashboard.console.allow.clear()
    dashboard.assert_no_console_errors()


def test_view_is_open_but_starting_a_run_asks_for_the_token(dashboard: Dashboard, tmp_path: Path, expect: Any) -> None:
    control_only = Service(data_dir=tmp_path / "data", log_path=tmp_path / "service.log", extra_args=("--token", TOKEN))
    control_only.start()
    try:
        page = dashboard.page
        dashboard.open(base_url=control_only.url)  # no prompt: viewing is open
        dialog = page.get_by_role("dialog", name="Access token")
        expect(dialog).to_be_hidden()
        dashboard.console.allow.append(unauthorized)
        page.get_by_role("button", name="Start run").click()
        expect(dialog).to_be_visible()
        page.get_by_label("Token", exact=True).fill(TOKEN)
        page.get_by_role("button", name="Continue").click()
        state = dashboard.wait_state("s => s.runId !== null && s.connection === 'live'", 30)
        assert control_only.api("GET", f"/api/runs/{state['runId']}").json()["status"] in ("queued", "running")
        page.get_by_role("button", name="Stop run").click()
        dashboard.wait_state("s => s.connection === 'ended'", 30)
        dashboard.console.allow.clear()
        dashboard.assert_no_console_errors()
    finally:
        control_only.stop()
