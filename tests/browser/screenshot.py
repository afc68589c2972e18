"""Save a screenshot of the dashboard in the middle of a run, for the README: ``docs/dashboard.png``.

    .venv/bin/python tests/browser/screenshot.py [--out docs/dashboard.png] [--world room2] [--steps 45]

Starts its own service on a free loopback port with a temporary data directory, drives Debian's
Chromium (see ``browser_kit.find_chromium``), and stops everything when done.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from browser_kit import CHROMIUM_ARGS, ROOT, Service, find_chromium


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "dashboard.png")
    parser.add_argument("--world", default="room2")
    parser.add_argument("--speed", default="20")
    parser.add_argument("--steps", type=int, default=45, help="steps into the run when the picture is taken")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=860)
    args = parser.parse_args()

    executable = find_chromium()
    if executable is None:
        print("no Chromium found: install Debian's chromium or set SONARSLAM_CHROMIUM", file=sys.stderr)
        return 2
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
        service = Service(data_dir=Path(tmp) / "data", log_path=Path(tmp) / "service.log")
        service.start()
        browser = pw.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": args.width, "height": args.height})
            page.goto(service.url + "/")
            page.wait_for_function("document.querySelector('#world option')", timeout=20_000)
            page.get_by_label("World", exact=True).select_option(args.world)
            page.get_by_label("Speed (times real time)", exact=True).select_option(args.speed)
            page.get_by_role("button", name="Start run").click()
            page.wait_for_function(
                f"(s => s.connection === 'live' && s.status === 'running' && s.steps >= {args.steps})"
                "(window.sonarslam.state())",
                timeout=120_000,
            )
            page.evaluate("document.activeElement && document.activeElement.blur(); window.scrollTo(0, 0)")
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            page.get_by_role("button", name="Stop run").click()
            page.wait_for_function("window.sonarslam.state().connection === 'ended'", timeout=30_000)
        finally:
            browser.close()
            service.stop()
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
