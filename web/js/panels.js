// The panels around the map: run status and scores, the run list, the world and speed choosers.

export const SPEEDS = [1, 2, 5, 10, 20, 50, 100, 200, 'max'];
const ACTIVE = new Set(['queued', 'running']);

export function isActive(status) {
  return ACTIVE.has(status);
}

// -- formatting ------------------------------------------------------------------------------------
const DASH = '\u2013';

function num(value, digits) {
  return typeof value === 'number' && Number.isFinite(value) ? value.toFixed(digits) : DASH;
}

export function formatSpeed(speed) {
  if (speed === 'max') return 'max';
  if (typeof speed === 'number' && Number.isFinite(speed)) return `${speed}\u00d7`;
  if (typeof speed === 'string' && speed) return speed;
  return DASH;
}

export function formatDuration(seconds) {
  if (typeof seconds !== 'number' || !Number.isFinite(seconds)) return DASH;
  if (seconds < 60) return `${seconds.toFixed(1)} s`;
  const m = Math.floor(seconds / 60);
  const s = Math.floor(seconds - m * 60);
  if (m < 60) return `${m} min ${String(s).padStart(2, '0')} s`;
  return `${Math.floor(m / 60)} h ${String(m % 60).padStart(2, '0')} min`;
}

export function formatShare(share) {
  return typeof share === 'number' && Number.isFinite(share) ? `${(share * 100).toFixed(1)} %` : DASH;
}

/** Fill a <select> with the speed choices, keeping `current` selected (adding it if unusual). */
export function fillSpeedOptions(select, current) {
  const values = [...SPEEDS];
  if (current !== undefined && current !== null && !values.includes(current)) values.push(current);
  select.replaceChildren(
    ...values.map((v) => {
      const opt = document.createElement('option');
      opt.value = String(v);
      opt.textContent = v === 'max' ? 'As fast as possible' : `${v}\u00d7`;
      return opt;
    }),
  );
  if (current !== undefined && current !== null) select.value = String(current);
}

export function parseSpeed(text) {
  if (text === 'max') return 'max';
  const n = Number(text);
  return Number.isFinite(n) && n > 0 ? n : 'max';
}

// -- runs: the service's JSON is read defensively, since field names may grow ----------------------
export function runId(run) {
  return String(run.id ?? run.run_id ?? '');
}

function pick(run, key) {
  return run[key] ?? run.params?.[key] ?? run.request?.[key] ?? run.config?.[key];
}

export function runLabel(run) {
  const parts = [pick(run, 'world'), pick(run, 'mapper')].filter(Boolean);
  return parts.length ? parts.join(' \u00b7 ') : runId(run);
}

function runTime(run) {
  const t = run.created_at ?? run.started_at ?? run.created ?? null;
  const ms = typeof t === 'number' ? t * (t < 1e12 ? 1000 : 1) : Date.parse(t ?? '');
  return Number.isFinite(ms) ? ms : null;
}

/** Newest first when the service gives times; otherwise its own order. */
export function sortRuns(runs) {
  if (runs.every((r) => runTime(r) !== null)) return [...runs].sort((a, b) => runTime(b) - runTime(a));
  return runs;
}

// -- the status panel ------------------------------------------------------------------------------
export class StatusPanel {
  constructor(doc) {
    const el = (id) => doc.getElementById(id);
    this.f = {
      status: el('stat-status'),
      terminated: el('stat-terminated'),
      explored: el('stat-explored'),
      steps: el('stat-steps'),
      time: el('stat-time'),
      speed: el('stat-speed'),
      action: el('stat-action'),
      frontier: el('stat-frontier'),
      f1: el('stat-f1'),
      precision: el('stat-precision'),
      errorRatio: el('stat-error-ratio'),
    };
    this.truthRows = [...doc.querySelectorAll('.truth-metric')];
  }

  /** `s` = { run, progress, metrics, action } as the page currently knows them. */
  render(s) {
    const run = s.run || {};
    const progress = s.progress || {};
    const metrics = s.metrics || {};
    const f = this.f;
    f.status.textContent = run.status || DASH;
    f.terminated.textContent = run.terminated_by || DASH;
    f.explored.textContent = formatShare(progress.explored);
    f.steps.textContent = typeof progress.step === 'number' ? String(progress.step) : DASH;
    f.time.textContent = formatDuration(progress.sim_time_s);
    f.speed.textContent = formatSpeed(run.speed);
    f.action.textContent = s.action || DASH;
    f.frontier.textContent = typeof progress.frontier === 'number' ? String(progress.frontier) : DASH;
    f.f1.textContent = num(metrics.f1, 3);
    f.precision.textContent = num(metrics.precision, 3);
    f.errorRatio.textContent = num(metrics.error_ratio, 3);
    // Scores against the truth only exist for simulated runs.
    const simulated = !run.hardware || run.hardware === 'sim';
    for (const row of this.truthRows) row.hidden = !simulated;
  }
}

// -- the run list ----------------------------------------------------------------------------------
/**
 * Render runs as buttons (open) with a delete button for runs that are over. Rebuilds only when the
 * set or order of runs changed, so keyboard focus inside the list survives the periodic refresh.
 */
export function renderRunList(list, runs, currentId, { onOpen, onDelete }) {
  const ids = runs.map(runId);
  const existing = [...list.children].map((li) => li.dataset.id);
  const same = ids.length === existing.length && ids.every((id, i) => id === existing[i]);
  if (!same) {
    const focusedId = list.contains(document.activeElement) ? document.activeElement.closest('li')?.dataset.id : null;
    const focusedDelete = document.activeElement?.classList.contains('delete');
    list.replaceChildren(...runs.map((run) => buildRunItem(run, onOpen, onDelete)));
    if (focusedId) {
      const li = list.querySelector(`li[data-id="${CSS.escape(focusedId)}"]`);
      li?.querySelector(focusedDelete ? '.delete' : '.run-item')?.focus();
    }
  }
  runs.forEach((run, i) => updateRunItem(list.children[i], run, currentId));
}

function buildRunItem(run, onOpen, onDelete) {
  const id = runId(run);
  const li = document.createElement('li');
  li.dataset.id = id;
  const open = document.createElement('button');
  open.type = 'button';
  open.className = 'run-item';
  const name = document.createElement('span');
  name.className = 'name';
  const badge = document.createElement('span');
  badge.className = 'badge';
  const small = document.createElement('span');
  small.className = 'id';
  small.textContent = id;
  open.append(name, badge, small);
  open.addEventListener('click', () => onOpen(id));
  const del = document.createElement('button');
  del.type = 'button';
  del.className = 'delete';
  del.textContent = 'Delete';
  del.setAttribute('aria-label', `Delete run ${id}`);
  del.addEventListener('click', () => onDelete(id));
  li.append(open, del);
  return li;
}

function updateRunItem(li, run, currentId) {
  const id = runId(run);
  const status = run.status || 'unknown';
  const open = li.querySelector('.run-item');
  li.querySelector('.name').textContent = runLabel(run);
  const badge = li.querySelector('.badge');
  badge.textContent = status;
  badge.dataset.status = status;
  open.setAttribute('aria-label', `Open run ${runLabel(run)}, ${status}, ${id}`);
  if (id === currentId) open.setAttribute('aria-current', 'true');
  else open.removeAttribute('aria-current');
  li.querySelector('.delete').disabled = isActive(status);
}

// -- worlds ----------------------------------------------------------------------------------------
function worldName(w) {
  return typeof w === 'string' ? w : String(w.name ?? w.id ?? '');
}

function isUploaded(w) {
  if (typeof w !== 'object' || w === null) return false;
  if (typeof w.builtin === 'boolean') return !w.builtin;
  if (typeof w.built_in === 'boolean') return !w.built_in;
  const source = w.source ?? w.kind ?? w.origin;
  return source === 'uploaded' || source === 'upload' || source === 'user';
}

/** Fill the world <select>, built-in worlds and uploaded ones in separate groups. */
export function fillWorlds(select, worlds, preferred) {
  const previous = preferred || select.value;
  const groups = [
    ['Built-in', worlds.filter((w) => !isUploaded(w))],
    ['Uploaded', worlds.filter((w) => isUploaded(w))],
  ];
  const nodes = [];
  for (const [label, items] of groups) {
    if (items.length === 0) continue;
    const group = document.createElement('optgroup');
    group.label = label;
    for (const w of items) {
      const opt = document.createElement('option');
      opt.value = worldName(w);
      const description = typeof w === 'object' && w && w.description ? ` \u2013 ${w.description}` : '';
      opt.textContent = `${worldName(w)}${description}`.slice(0, 80);
      group.append(opt);
    }
    nodes.push(group);
  }
  select.replaceChildren(...nodes);
  const names = worlds.map(worldName);
  if (previous && names.includes(previous)) select.value = previous;
}
