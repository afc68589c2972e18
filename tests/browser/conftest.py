"""Browser tests: a real service on a loopback port, driven through Debian's Chromium by Playwright.

Chromium is found at ``$SONARSLAM_CHROMIUM``, else ``chromium`` / ``chromium-browser`` on the PATH, else
``/usr/bin/chromium`` (Playwright's own browser downloads are never used). Without it the tests skip,
except under CI (``$CI`` set), where they fail.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from browser_kit import CHROMIUM_ARGS, VIEWPORT, ConsoleWatch, Dashboard, Service, find_chromium, unavailable


@pytest.fixture(scope="session")
def playwright_api() -> Any:
    try:
        import playwright.sync_api as api
    except ImportError:
        unavailable("the playwright package is not installed")
    return api


@pytest.fixture(scope="session")
def browser(playwright_api: Any) -> Iterator[Any]:
    executable = find_chromium()
    if executable is None:
        unavailable("no Chromium executable found")
    with playwright_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS, timeout=30_000)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def expect(playwright_api: Any) -> Any:
    """Playwright's auto-waiting assertions (imported only once the browser is known to be there)."""
    playwright_api.expect.set_options(timeout=20_000)
    return playwright_api.expect


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    """One service per test module, with its own data directory."""
    base = tmp_path_factory.mktemp("service")
    svc = Service(data_dir=base / "data", log_path=base / "service.log")
    svc.start()
    try:
        yield svc
    finally:
        svc.stop()


@pytest.fixture
def dashboard(browser: Any, service: Service) -> Iterator[Dashboard]:
    context = browser.new_context(viewport=VIEWPORT, accept_downloads=True)
    context.set_default_timeout(20_000)
    page = context.new_page()
    console = ConsoleWatch()
    page.on("console", console.on_console)
    page.on("pageerror", console.on_page_error)
    try:
        yield Dashboard(page, service, console)
    finally:
        if console.tolerated:
            print("tolerated browser messages:", *console.tolerated, sep="\n  ")
        context.close()
