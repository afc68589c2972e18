// The dashboard: wires the REST client, the live socket, the map view and the panels together.
// Test hook: `window.sonarslam` (documented in web/README.md).

import { Api, ApiError, adoptTokenFromUrl } from './api.js';
import { CellLayer, MAP_PALETTE, TRUTH_PALETTE, decodeBase64 } from './gridlayer.js';
import { LiveRun, applyStep, isTerminal, viewFromSnapshot } from './live.js';
import { MapView } from './mapview.js';
import {
  StatusPanel,
  fillSpeedOptions,
  fillWorlds,
  isActive,
  parseSpeed,
  renderRunList,
  runId,
  runLabel,
  sortRuns,
} from './panels.js';

const $ = (id) => document.getElementById(id);
const TRAIL_MAX = 5000; // as many positions as a snapshot carries
const RUNS_POLL_MS = 3000;
const RUNS_POLL_MAX_MS = 30_000;

// -- the token prompt ------------------------------------------------------------------------------
function askToken(why) {
  const dialog = $('token-dialog');
  const input = $('token-input');
  $('token-reason').textContent = why;
  input.value = '';
  return new Promise((resolve) => {
    dialog.addEventListener(
      'close',
      () => resolve(dialog.returnValue === 'ok' && input.value.trim() ? input.value.trim() : null),
      { once: true },
    );
    dialog.returnValue = '';
    if (!dialog.open) dialog.showModal();
    input.focus();
  });
}

const api = new Api({ askToken });
adoptTokenFromUrl(api);

// -- state -----------------------------------------------------------------------------------------
const mapLayer = new CellLayer(MAP_PALETTE);
const truthLayer = new CellLayer(TRUTH_PALETTE);
const view = new MapView($('map'), {
  mapLayer,
  truthLayer,
  scaleBar: { bar: $('scale-bar'), label: $('scale-label') },
});
const panel = new StatusPanel(document);
const sessionRef = { current: null };
let runView = null; // the open run's pose, trail, sweep, target, action, progress and metrics

const app = {
  runId: null,
  live: null,
  run: {},
  progress: null,
  metrics: null,
  action: null,
  runs: [],
  counters: { snapshots: 0, steps: 0, restarts: 0 },
};

function say(id, text, kind = 'error') {
  const el = $(id);
  el.textContent = text || '';
  el.classList.toggle('info', kind === 'info');
}

function explain(err) {
  return err instanceof ApiError ? err.message : String(err && err.message ? err.message : err);
}

// -- rendering the run panel -----------------------------------------------------------------------
let panelFrame = 0;
let shownSpeed; // the run speed the live speed control was last set to
function renderPanel() {
  if (panelFrame) return;
  panelFrame = requestAnimationFrame(() => {
    panelFrame = 0;
    panel.render(app);
    const active = app.runId !== null && isActive(app.run.status);
    $('stop').disabled = !active;
    $('speed-live').disabled = !active;
    $('speed-apply').disabled = !active;
    // Follow the run's speed only when it changes, so a choice being made is not overwritten.
    if (app.run.speed !== undefined && app.run.speed !== shownSpeed) {
      shownSpeed = app.run.speed;
      fillSpeedOptions($('speed-live'), shownSpeed);
    }
  });
}

const CONNECTION_TEXT = {
  idle: 'No run open',
  connecting: 'Connecting\u2026',
  live: 'Live',
  closed: 'No run open',
  gone: 'Run not found',
  unauthorized: 'Access token required',
};

function showConnection(state, info = {}) {
  const el = $('conn');
  el.dataset.state = state;
  let text = CONNECTION_TEXT[state] || state;
  if (state === 'reconnecting') {
    text = info.delayMs ? `Reconnecting\u2026 (next try in ${Math.ceil(info.delayMs / 1000)} s)` : 'Reconnecting\u2026';
  } else if (state === 'ended') {
    text = `Run ${app.run.status || 'ended'}: final map`;
  } else if (state === 'live' && !isActive(app.run.status) && app.run.status) {
    text = `Run ${app.run.status}`;
  }
  el.textContent = text;
}

// -- the live run ----------------------------------------------------------------------------------
function cellsFrom(value) {
  if (typeof value === 'string') return decodeBase64(value);
  if (Array.isArray(value)) return Uint8Array.from(value.flat());
  return null;
}

function onSnapshot(msg, { restarted }) {
  app.counters.snapshots += 1;
  if (restarted) {
    app.counters.restarts += 1;
    // A new server: the world list and the runs may all have changed.
    loadWorlds();
    refreshRuns();
  }
  const run = msg.run || {};
  const g = msg.grid || {};
  const grid = {
    rows: g.rows,
    cols: g.cols,
    resolution: g.resolution ?? run.resolution,
    origin: Array.isArray(g.origin) ? g.origin : [0, 0],
  };
  mapLayer.reset(grid.rows, grid.cols, cellsFrom(msg.cells) || new Uint8Array(0));
  const truth = cellsFrom(msg.truth);
  if (truth) truthLayer.reset(grid.rows, grid.cols, truth);
  else truthLayer.clear();
  const truthBox = $('layer-truth');
  truthBox.disabled = !truth;
  if (!truth) truthBox.checked = false;
  view.setLayer('truth', truthBox.checked);

  view.robot = msg.robot || null;
  runView = viewFromSnapshot(msg);
  showRunView();
  view.setGrid(grid);
  $('map-empty').hidden = true;

  app.run = { ...run };
  $('run-title').textContent = `${runLabel({ ...run, id: app.runId })} (${app.runId})`;
  renderPanel();
}

function onStep(msg) {
  app.counters.steps += 1;
  if (!runView) return;
  mapLayer.patch(msg.cells || []);
  applyStep(runView, msg);
  const trail = runView.trail;
  if (trail.length > TRAIL_MAX) trail.splice(0, trail.length - TRAIL_MAX);
  showRunView();
  view.requestDraw();
  renderPanel();
}

/** The run's view (folded by live.js, in metres) to the map and the panel. */
function showRunView() {
  view.pose = runView.pose;
  view.trail = runView.trail;
  view.sweep = runView.sweep;
  view.target = runView.target;
  app.progress = runView.progress;
  app.metrics = runView.metrics;
  app.action = runView.action;
}

function onStatus(msg) {
  if (msg.status) app.run.status = msg.status;
  if ('terminated_by' in msg) app.run.terminated_by = msg.terminated_by;
  if ('speed' in msg) app.run.speed = msg.speed;
  if (msg.event === 'error' && msg.message) say('run-message', `The run failed: ${msg.message}`);
  if (msg.event !== 'progress' && msg.event !== 'speed') refreshRuns();
  if (runView) {
    if (msg.metrics) runView.metrics = msg.metrics; // the closing scores, at full precision
    if (msg.progress) runView.progress = { ...msg.progress };
    if (isTerminal(msg.status)) runView.action = null;
    showRunView();
  }
  renderPanel();
  showConnection($('conn').dataset.state);
}

async function checkGone(id) {
  try {
    await api.run(id);
    return false;
  } catch (err) {
    return err instanceof ApiError && err.status === 404;
  }
}

function setDownloads(id) {
  for (const a of document.querySelectorAll('#downloads a')) {
    const file = a.dataset.file;
    if (id) {
      a.href = api.fileUrl(id, file);
      a.download = `${id}_${file}`;
      a.removeAttribute('aria-disabled');
    } else {
      a.removeAttribute('href');
      a.removeAttribute('download');
      a.setAttribute('aria-disabled', 'true');
    }
  }
}

function closeRun() {
  if (app.live) app.live.close();
  app.live = null;
  runView = null;
  app.runId = null;
  app.run = {};
  app.progress = null;
  app.metrics = null;
  app.action = null;
  shownSpeed = undefined;
  mapLayer.clear();
  truthLayer.clear();
  view.clear();
  $('map-empty').hidden = false;
  $('run-title').textContent = '';
  setDownloads(null);
  say('run-message', '');
  showConnection('idle');
  renderPanel();
  renderRuns();
}

function openRun(id) {
  if (!id) return;
  closeRun();
  app.runId = id;
  const known = app.runs.find((r) => runId(r) === id);
  app.run = known ? { ...known } : {};
  $('run-title').textContent = `${known ? runLabel(known) : ''} (${id})`;
  setDownloads(id);
  if (window.location.hash !== `#run=${encodeURIComponent(id)}`) {
    window.history.replaceState(null, '', `#run=${encodeURIComponent(id)}`);
  }
  const live = new LiveRun(
    id,
    {
      onSnapshot,
      onStep,
      onStatus,
      onConnection: (state, info) => {
        if (app.live === live) showConnection(state, info);
      },
      checkGone: () => checkGone(id),
      obtainToken: () => api.obtainToken('The live map requires an access token.'),
      // A failed handshake may be a missing token: from the second try on, send it anyway.
      getToken: () => (api.viewNeedsToken || live.attempt > 0 ? api.token : ''),
    },
    sessionRef,
  );
  app.live = live;
  live.start();
  renderPanel();
  renderRuns();
}

// -- the run list ----------------------------------------------------------------------------------
function renderRuns() {
  renderRunList($('run-list'), app.runs, app.runId, { onOpen: openRun, onDelete: deleteRun });
  $('runs-empty').hidden = app.runs.length > 0;
}

let pollDelay = RUNS_POLL_MS;
let pollTimer = 0;
async function refreshRuns() {
  clearTimeout(pollTimer);
  try {
    app.runs = sortRuns(await api.runs());
    renderRuns();
    pollDelay = RUNS_POLL_MS;
  } catch {
    pollDelay = Math.min(RUNS_POLL_MAX_MS, pollDelay * 2); // the service is away: ask less often
  }
  clearTimeout(pollTimer); // another refresh may have finished meanwhile: keep a single timer
  pollTimer = setTimeout(refreshRuns, pollDelay);
}

async function deleteRun(id) {
  if (!window.confirm(`Delete run ${id} and its files?`)) return;
  try {
    await api.deleteRun(id);
    if (app.runId === id) {
      closeRun();
      window.history.replaceState(null, '', window.location.pathname + window.location.search);
    }
  } catch (err) {
    say('run-message', `Could not delete the run: ${explain(err)}`);
  }
  refreshRuns();
}

// -- forms -----------------------------------------------------------------------------------------
async function loadWorlds(preferred) {
  try {
    fillWorlds($('world'), await api.worlds(), preferred);
    say('start-message', '');
  } catch (err) {
    say('start-message', `Could not load the worlds: ${explain(err)}`);
  }
}

/** Prefill the start form from the service's default run configuration (GET /api/config). */
async function loadDefaults() {
  let config = {};
  try {
    config = (await api.config()) || {};
  } catch {
    return {}; // the form's own defaults are fine
  }
  const d = config.slam || config.defaults || config;
  if (typeof d.resolution === 'number') $('resolution').value = String(d.resolution);
  if (d.mapper === 'logodds' || d.mapper === 'paper') $('mapper').value = d.mapper;
  if (Number.isInteger(d.seed)) $('seed').value = String(d.seed);
  if (d.speed !== undefined && d.speed !== null) fillSpeedOptions($('speed'), d.speed);
  if (typeof d.time_limit_s === 'number') $('time-limit').placeholder = `default ${d.time_limit_s}`;
  if (typeof d.end_when_mapped === 'boolean') $('full-walk').checked = !d.end_when_mapped;
  return d;
}

$('start-form').addEventListener('submit', async (e) => {
  e.preventDefault();
  const form = e.currentTarget;
  if (!form.reportValidity()) return;
  const params = {
    world: $('world').value,
    mapper: $('mapper').value,
    resolution: Number($('resolution').value),
    seed: Number.parseInt($('seed').value, 10),
    speed: parseSpeed($('speed').value),
  };
  const limit = $('time-limit').value.trim();
  if (limit) params.time_limit_s = Number(limit);
  params.end_when_mapped = !$('full-walk').checked;
  const button = $('start-button');
  button.disabled = true;
  say('start-message', '');
  try {
    const created = await api.startRun(params);
    const id = runId(created || {});
    say('start-message', `Started run ${id}.`, 'info');
    await refreshRuns();
    openRun(id);
  } catch (err) {
    say('start-message', `Could not start the run: ${explain(err)}`);
  } finally {
    button.disabled = false;
  }
});

$('upload-form').addEventListener('submit', async (e) => {
  e.preventDefault();
  const file = $('world-file').files[0];
  if (!file) return;
  say('upload-message', '');
  try {
    const added = (await api.uploadWorld(file)) || {};
    const name = added.name ?? added.world?.name ?? file.name.replace(/\.toml$/i, '');
    await loadWorlds(name);
    $('world-file').value = '';
    say('upload-message', `Added world ${name}.`, 'info');
  } catch (err) {
    say('upload-message', `Could not add the world: ${explain(err)}`);
  }
});

$('speed-form').addEventListener('submit', async (e) => {
  e.preventDefault();
  if (!app.runId) return;
  const speed = parseSpeed($('speed-live').value);
  try {
    await api.setSpeed(app.runId, speed);
    app.run.speed = speed;
    say('run-message', '');
    renderPanel();
  } catch (err) {
    say('run-message', `Could not change the speed: ${explain(err)}`);
  }
});

$('stop').addEventListener('click', async () => {
  if (!app.runId) return;
  try {
    await api.stopRun(app.runId);
    say('run-message', '');
  } catch (err) {
    say('run-message', `Could not stop the run: ${explain(err)}`);
  }
});

$('refresh-runs').addEventListener('click', () => refreshRuns());

$('downloads').addEventListener('click', (e) => {
  const a = e.target.closest('a[href]');
  if (!a || !api.token) return; // without a token the browser fetches the link itself
  e.preventDefault();
  api.download(a.href, a.download).catch((err) => say('run-message', `Download failed: ${explain(err)}`));
});

// -- the map toolbar -------------------------------------------------------------------------------
$('zoom-in').addEventListener('click', () => view.zoomAt(1.25));
$('zoom-out').addEventListener('click', () => view.zoomAt(0.8));
$('zoom-fit').addEventListener('click', () => view.fit());
for (const name of ['robot', 'trail', 'beams', 'target', 'truth']) {
  const box = $(`layer-${name}`);
  view.setLayer(name, box.checked);
  box.addEventListener('change', () => view.setLayer(name, box.checked));
}

window.addEventListener('hashchange', () => {
  const id = runFromHash();
  if (id && id !== app.runId) openRun(id);
});

function runFromHash() {
  const m = /^#run=(.+)$/.exec(window.location.hash);
  return m ? decodeURIComponent(m[1]) : null;
}

// -- the test hook ---------------------------------------------------------------------------------
window.sonarslam = Object.freeze({
  version: 1,
  /** Viewport coordinates (CSS px) of the centre of cell [row, col], or null without a map. */
  cellToClient: (row, col) => view.cellToClient(row, col),
  /** Viewport coordinates (CSS px) of a map-frame point [m], or null without a map. */
  worldToClient: (x, y) => view.worldToClient(x, y),
  /** The map as the page holds it: rows of codes 0 free, 1 occupied, 2 unknown. */
  cells: () => mapLayer.toRows(),
  /** What the page knows about the open run and its connection. */
  state: () => ({
    runId: app.runId,
    connection: app.live ? app.live.state : 'idle',
    session: sessionRef.current,
    seq: app.live ? app.live.lastSeq : null,
    status: app.run.status ?? null,
    terminatedBy: app.run.terminated_by ?? null,
    grid: view.grid,
    pose: view.pose,
    trailLength: view.trail.length,
    reconnects: app.live ? app.live.reconnects : 0,
    ...app.counters,
  }),
  openRun: (id) => openRun(id),
});

// -- start -----------------------------------------------------------------------------------------
fillSpeedOptions($('speed'), 20);
fillSpeedOptions($('speed-live'), 20);
setDownloads(null);
renderPanel();
loadDefaults().then((defaults) => loadWorlds(typeof defaults.world === 'string' ? defaults.world : undefined));
refreshRuns();
const initial = runFromHash();
if (initial) openRun(initial);
