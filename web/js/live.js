// One viewer's WebSocket to a run (docs/protocol.md): hello, snapshot, gap-free steps, resync, reconnect;
// and the run's view (pose, sweep, target, progress, ...) folded from a snapshot and the steps after it.

const TERMINAL = new Set(['finished', 'stopped', 'error', 'interrupted']);
const BACKOFF_FIRST_MS = 500;
const BACKOFF_MAX_MS = 5000;
const PING_EVERY_MS = 15_000;
const SILENCE_LIMIT_MS = 40_000; // no frame at all for this long: the link is dead, reconnect

export function isTerminal(status) {
  return TERMINAL.has(status);
}

// -- the run's view: steps carry only what changed, in integer units ---------------------------------
const MILLI = 1000; // positions in millimetres, angles in milliradians
const CENTI = 100; // sonar ranges in centimetres

function poseOf(p) {
  return Array.isArray(p) && p.length >= 3 ? { x: p[0] / MILLI, y: p[1] / MILLI, theta: p[2] / MILLI } : null;
}

function pointOf(p) {
  return Array.isArray(p) && p.length >= 2 ? [p[0] / MILLI, p[1] / MILLI] : null;
}

function sweepOf(ranges) {
  return Array.isArray(ranges) ? ranges.map((v) => (typeof v === 'number' ? v / CENTI : null)) : null;
}

/** What a snapshot says about the run, in metres and radians: {pose, trail, sweep, target, action, progress, metrics}. */
export function viewFromSnapshot(msg) {
  return {
    pose: poseOf(msg.pose),
    trail: Array.isArray(msg.trail) ? msg.trail.map(pointOf).filter(Boolean) : [],
    sweep: sweepOf(msg.sweep),
    target: pointOf(msg.target),
    action: msg.action ?? null,
    progress: { ...(msg.progress || {}) },
    metrics: msg.metrics ?? null,
  };
}

/** Fold a step (or a merged run of steps) into a view: a field the step leaves out has not changed. */
export function applyStep(view, msg) {
  if ('pose' in msg) view.pose = poseOf(msg.pose);
  if ('sweep' in msg) view.sweep = sweepOf(msg.sweep);
  if ('target' in msg) view.target = pointOf(msg.target);
  if ('action' in msg) view.action = msg.action;
  if ('metrics' in msg) view.metrics = msg.metrics;
  const progress = { ...view.progress, step: msg.step ?? msg.seq };
  if ('t_s' in msg) progress.sim_time_s = msg.t_s;
  if ('explored' in msg) progress.explored = msg.explored;
  if ('frontier' in msg) progress.frontier = msg.frontier;
  view.progress = progress;
  if (Array.isArray(msg.trail)) {
    // A merged step: where the robot ended each of the steps it stands for, before the last.
    for (const point of msg.trail.map(pointOf)) if (point) view.trail.push(point);
  }
  if (view.pose) view.trail.push([view.pose.x, view.pose.y]);
  return view;
}

// -- the socket ------------------------------------------------------------------------------------
/** The WebSocket URL for a path on this page's host; the token rides in the query because a
 * browser cannot set headers on a WebSocket handshake. */
export function wsUrl(path, token) {
  const url = new URL(path, window.location.href);
  url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
  if (token) url.searchParams.set('token', token);
  return url.href;
}

/**
 * Follows one run. Handlers (all optional):
 *   onSnapshot(msg, {restarted})  the full state; `restarted` when the server's session changed
 *   onStep(msg)                   one step (or a merged run of steps), in order, without gaps
 *   onStatus(msg)                 a status event
 *   onConnection(state, info)     'connecting' | 'live' | 'reconnecting' | 'ended' | 'gone' | 'closed' | 'unauthorized'
 *   checkGone()                   async; true if the run no longer exists (asked after failed reconnects)
 *   obtainToken()                 async; true once the user gave a (new) token
 *   getToken()                    the current token, or ''
 *
 * `session` is shared through `sessionRef` so that a server restart seen by one run's socket is
 * recognised by the next one too.
 */
export class LiveRun {
  constructor(runId, handlers, sessionRef = { current: null }) {
    this.runId = runId;
    this.h = handlers;
    this.sessionRef = sessionRef;
    this.ws = null;
    this.lastSeq = null; // seq of the last step folded into our grid
    this.awaitingSnapshot = true;
    this.terminal = false;
    this.stopped = false;
    this.attempt = 0; // consecutive connection attempts that never got a hello
    this.reconnects = 0;
    this.timer = null;
    this.pingTimer = null;
    this.lastFrameAt = 0;
    this.state = 'idle';
  }

  start() {
    this._open();
  }

  /** Stop following the run; no reconnects. */
  close() {
    this.stopped = true;
    clearTimeout(this.timer);
    clearInterval(this.pingTimer);
    if (this.ws) {
      const ws = this.ws;
      this.ws = null;
      if (ws.readyState === WebSocket.CONNECTING || ws.readyState === WebSocket.OPEN) ws.close(1000, 'viewer left');
    }
    this._setState('closed');
  }

  /** Ask for a fresh snapshot (also used by the page when it is in doubt). */
  resync() {
    this.awaitingSnapshot = true;
    this._send({ type: 'resync' });
  }

  _setState(state, info = {}) {
    this.state = state;
    this.h.onConnection?.(state, info);
  }

  _send(msg) {
    // Sending on a closing socket makes Chromium log an error, so check first.
    if (this.ws && this.ws.readyState === WebSocket.OPEN) this.ws.send(JSON.stringify(msg));
  }

  _open() {
    if (this.stopped) return;
    clearTimeout(this.timer);
    this._setState(this.reconnects > 0 ? 'reconnecting' : 'connecting', { attempt: this.attempt });
    this.helloSeen = false;
    const ws = new WebSocket(wsUrl(`/ws/runs/${encodeURIComponent(this.runId)}`, this.h.getToken?.()));
    this.ws = ws;
    ws.onmessage = (ev) => {
      if (ws !== this.ws) return;
      this.lastFrameAt = Date.now();
      let msg;
      try {
        msg = JSON.parse(ev.data);
      } catch {
        return; // not ours to understand; the protocol only sends JSON text
      }
      this._onMessage(msg);
    };
    ws.onclose = (ev) => {
      if (ws !== this.ws) return;
      this._onClose(ev);
    };
    ws.onerror = () => {
      // A close event always follows; reconnecting is decided there.
    };
    ws.onopen = () => {
      if (ws !== this.ws) return;
      this.lastFrameAt = Date.now();
      clearInterval(this.pingTimer);
      this.pingTimer = setInterval(() => this._keepAlive(), PING_EVERY_MS);
    };
  }

  _keepAlive() {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return;
    if (Date.now() - this.lastFrameAt > SILENCE_LIMIT_MS) {
      this.ws.close(4000, 'no traffic');
      return;
    }
    this._send({ type: 'ping' });
  }

  _onMessage(msg) {
    switch (msg.type) {
      case 'hello': {
        this.helloSeen = true;
        this.attempt = 0;
        const known = this.sessionRef.current;
        this.restarted = Boolean(known && msg.session && msg.session !== known);
        if (msg.session) this.sessionRef.current = msg.session;
        if (this.restarted) this.lastSeq = null; // a new server: nothing we hold is valid
        this.awaitingSnapshot = true;
        break;
      }
      case 'snapshot': {
        this.lastSeq = Number.isInteger(msg.seq) ? msg.seq : null;
        this.awaitingSnapshot = false;
        const restarted = Boolean(this.restarted);
        this.restarted = false;
        this.h.onSnapshot?.(msg, { restarted });
        const status = msg.run && msg.run.status;
        if (isTerminal(status)) this.terminal = true;
        this._setState(this.terminal ? 'ended' : 'live', { status });
        break;
      }
      case 'step': {
        if (this.awaitingSnapshot) return;
        if (this.lastSeq === null || msg.seq === this.lastSeq + 1) {
          this.lastSeq = msg.seq;
          this.h.onStep?.(msg);
        } else if (msg.seq > this.lastSeq + 1) {
          // A gap: our grid would be wrong from here on. Ask again and ignore steps until then.
          this.resync();
        }
        // seq <= lastSeq: already folded into the snapshot we hold.
        break;
      }
      case 'status': {
        this.h.onStatus?.(msg);
        if (isTerminal(msg.status) || isTerminal(msg.event)) this.terminal = true;
        break;
      }
      default:
        break; // pong and anything newer
    }
  }

  _onClose(ev) {
    clearInterval(this.pingTimer);
    this.ws = null;
    if (this.stopped) return;
    if (this.terminal) {
      // The run is over and the server said all it has: the grid now equals map.csv.
      this._setState('ended', { code: ev.code });
      return;
    }
    if (ev.code === 4401 || ev.code === 4403 || ev.code === 1008) {
      this._setState('unauthorized', { code: ev.code });
      Promise.resolve(this.h.obtainToken?.()).then((ok) => {
        if (ok && !this.stopped) this._open();
      });
      return;
    }
    if (ev.code === 4404) {
      this._setState('gone', { code: ev.code });
      return;
    }
    if (!this.helloSeen) this.attempt += 1;
    this.reconnects += 1;
    const delay = Math.min(BACKOFF_MAX_MS, BACKOFF_FIRST_MS * 2 ** Math.max(0, this.attempt - 1));
    this._setState('reconnecting', { attempt: this.attempt, delayMs: delay, code: ev.code });
    this.timer = setTimeout(() => this._retry(), delay);
  }

  async _retry() {
    if (this.stopped) return;
    // After a few failures, find out whether there is still a run to follow.
    if (this.attempt >= 2 && this.h.checkGone) {
      let gone = false;
      try {
        gone = await this.h.checkGone();
      } catch {
        gone = false;
      }
      if (this.stopped) return;
      if (gone) {
        this._setState('gone', {});
        return;
      }
    }
    this._open();
  }
}
