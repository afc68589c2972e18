"""The page's protocol rules (docs/protocol.md), played against a scripted socket inside the real browser:
gap-free steps, resync on a gap, ignoring stale steps, back-off reconnects, and a new session starting over."""

from __future__ import annotations

from typing import Any

import pytest
from browser_kit import Dashboard

pytestmark = pytest.mark.browser

# Runs in the page: replaces WebSocket by a scripted one, drives web/js/live.js, reports what it saw.
SCRIPT = """
async () => {
  const { LiveRun } = await import('/js/live.js');
  const sockets = [];
  const sent = [];
  class ScriptedSocket {
    static CONNECTING = 0;
    static OPEN = 1;
    static CLOSING = 2;
    static CLOSED = 3;
    constructor(url) {
      this.url = url;
      this.readyState = 1;
      sockets.push(this);
    }
    send(text) { sent.push(JSON.parse(text)); }
    close() { this.readyState = 3; }
  }
  const realSocket = window.WebSocket;
  window.WebSocket = ScriptedSocket;
  const seen = [];
  const live = new LiveRun('r-20260101-0001', {
    onSnapshot: (m, info) => seen.push(['snapshot', m.seq, info.restarted]),
    onStep: (m) => seen.push(['step', m.seq]),
    onStatus: (m) => seen.push(['status', m.event]),
    onConnection: (state) => seen.push(['connection', state]),
  }, { current: null });
  const wait = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
  const frame = (ws, msg) => ws.onmessage({ data: JSON.stringify(msg) });
  try {
    live.start();
    const first = sockets[0];
    frame(first, { type: 'hello', protocol: 2, session: 'A' });
    frame(first, { type: 'snapshot', seq: 5, run: { status: 'running' } });
    frame(first, { type: 'step', seq: 5 });   // already in the snapshot
    frame(first, { type: 'step', seq: 6 });
    frame(first, { type: 'step', seq: 8 });   // a gap: ask for a snapshot
    frame(first, { type: 'step', seq: 9 });   // ignored until it comes
    frame(first, { type: 'snapshot', seq: 9, run: { status: 'running' } });
    frame(first, { type: 'step', seq: 10 });
    first.readyState = 3;
    first.onclose({ code: 1006 });            // dropped
    await wait(900);                           // the first retry comes after 0.5 s
    const second = sockets[1];
    frame(second, { type: 'hello', protocol: 2, session: 'A' });
    frame(second, { type: 'snapshot', seq: 12, run: { status: 'running' } });
    frame(second, { type: 'step', seq: 13 });
    second.readyState = 3;
    second.onclose({ code: 1012 });
    await wait(900);
    const third = sockets[2];
    frame(third, { type: 'hello', protocol: 2, session: 'B' });   // the service restarted
    frame(third, { type: 'snapshot', seq: 2, run: { status: 'interrupted' } });
    frame(third, { type: 'status', seq: 2, event: 'interrupted', status: 'interrupted' });
    third.readyState = 3;
    third.onclose({ code: 1000 });
    await wait(900);                           // ended: no further attempt
    return { seen, sent, urls: sockets.map((s) => s.url), state: live.state, sockets: sockets.length };
  } finally {
    live.close();
    window.WebSocket = realSocket;
  }
}
"""


def test_live_client_follows_the_protocol_rules(dashboard: Dashboard) -> None:
    dashboard.open()
    result: dict[str, Any] = dashboard.page.evaluate(SCRIPT)
    seen = [tuple(e) for e in result["seen"]]
    data = [e for e in seen if e[0] != "connection"]
    assert data == [
        ("snapshot", 5, False),
        ("step", 6),
        ("snapshot", 9, False),
        ("step", 10),
        ("snapshot", 12, False),
        ("step", 13),
        ("snapshot", 2, True),
        ("status", "interrupted"),
    ]
    assert result["sent"] == [{"type": "resync"}]
    connections = [e[1] for e in seen if e[0] == "connection"]
    assert connections[0] == "connecting"
    assert connections.count("reconnecting") >= 2
    assert result["state"] == "ended"
    assert result["sockets"] == 3
    assert all(url.endswith("/ws/runs/r-20260101-0001") and url.startswith("ws://") for url in result["urls"])
    dashboard.assert_no_console_errors()


# Runs in the page: the run's view folded from a snapshot and steps that carry only what changed.
FOLD = """
async () => {
  const { viewFromSnapshot, applyStep } = await import('/js/live.js');
  const view = viewFromSnapshot({
    type: 'snapshot', seq: 3, pose: [1500, 300, 1571], trail: [[1500, 100], [1500, 300]],
    sweep: [32, 400], target: [1500, 500], action: 'explore',
    progress: { step: 3, sim_time_s: 4.5, explored: 0.25, frontier: 7 }, metrics: { f1: 0.5 },
  });
  applyStep(view, { type: 'step', seq: 4, t_s: 6.25, pose: [1500, 500, 1571], target: null });
  const merged = {
    type: 'step', seq: 7, merged: 3, t_s: 9.5, sweep: [40, 123], explored: 0.5, metrics: { f1: 0.75 },
    pose: [1700, 700, 0], trail: [[1500, 700], [1600, 700]],
  };
  applyStep(view, merged);
  applyStep(view, { type: 'step', seq: 8, step: 7, action: 'stop' });
  return view;
}
"""


def test_the_page_folds_steps_that_carry_only_what_changed(dashboard: Dashboard) -> None:
    dashboard.open()
    view: dict[str, Any] = dashboard.page.evaluate(FOLD)
    assert view["pose"] == {"x": 1.7, "y": 0.7, "theta": 0.0}  # metres and radians from mm and mrad
    # One point per step: a merged step brings the ends of the steps it stands for, then its pose.
    assert view["trail"] == [[1.5, 0.1], [1.5, 0.3], [1.5, 0.5], [1.5, 0.7], [1.6, 0.7], [1.7, 0.7], [1.7, 0.7]]
    assert view["sweep"] == [0.4, 1.23]  # metres from cm
    assert view["target"] is None  # sent as null: no target any more
    assert view["action"] == "stop"
    assert view["progress"] == {"step": 7, "sim_time_s": 9.5, "explored": 0.5, "frontier": 7}
    assert view["metrics"] == {"f1": 0.75}
