// REST client for the sonarslam service: JSON calls, file uploads and downloads, the bearer token.

const TOKEN_KEY = 'sonarslam.token';
const VIEW_KEY = 'sonarslam.viewNeedsToken';

/** A request the service refused or could not answer. `status` is 0 when it was unreachable. */
export class ApiError extends Error {
  constructor(status, message) {
    super(message);
    this.name = 'ApiError';
    this.status = status;
  }
}

/** FastAPI answers `{"detail": "..."}` or a list of validation errors; make one readable line. */
async function errorMessage(res) {
  let text = '';
  try {
    text = await res.text();
    const body = JSON.parse(text);
    const detail = body && (body.detail ?? body.message ?? body.error);
    if (typeof detail === 'string') return detail;
    if (Array.isArray(detail)) {
      return detail
        .map((d) => (d && d.msg ? `${(d.loc || []).filter((p) => p !== 'body').join('.')}: ${d.msg}` : String(d)))
        .join('; ');
    }
  } catch {
    // not JSON: fall through to the raw text
  }
  return text.trim().slice(0, 200) || `${res.status} ${res.statusText}`;
}

export class Api {
  /**
   * @param {object} opts
   * @param {(why: string) => Promise<string|null>} opts.askToken asks the user for a token after a 401
   */
  constructor({ askToken } = {}) {
    this.askToken = askToken;
    this._asking = null; // one prompt shared by every request that hit a 401 at the same time
  }

  get token() {
    try {
      return sessionStorage.getItem(TOKEN_KEY) || '';
    } catch {
      return '';
    }
  }

  set token(value) {
    try {
      if (value) sessionStorage.setItem(TOKEN_KEY, value);
      else sessionStorage.removeItem(TOKEN_KEY);
    } catch {
      // storage may be disabled; the token then lasts as long as the page
    }
  }

  /** Whether viewing (not only control) needs the token, as learnt from a 401 on a read. Only then
   * does the token go into a WebSocket URL, where it could end up in access logs. */
  get viewNeedsToken() {
    try {
      return sessionStorage.getItem(VIEW_KEY) === '1';
    } catch {
      return this._viewNeedsToken === true;
    }
  }

  set viewNeedsToken(value) {
    this._viewNeedsToken = value;
    try {
      sessionStorage.setItem(VIEW_KEY, value ? '1' : '0');
    } catch {
      // kept on the object only
    }
  }

  authHeaders() {
    const token = this.token;
    return token ? { Authorization: `Bearer ${token}` } : {};
  }

  /** Ask for a token once, however many requests are waiting for it. Resolves true if one was given. */
  async obtainToken(why) {
    if (!this.askToken) return false;
    if (!this._asking) {
      this._asking = this.askToken(why).finally(() => {
        this._asking = null;
      });
    }
    const token = await this._asking;
    if (token) this.token = token;
    return Boolean(token);
  }

  /**
   * One call. `json` sends a JSON body, `form` a FormData. Answers parsed JSON, text, or null for 204.
   * A 401 asks for a token and retries once the user gave one.
   */
  async request(method, path, { json, form } = {}) {
    for (;;) {
      const headers = { Accept: 'application/json', ...this.authHeaders() };
      let body;
      if (json !== undefined) {
        headers['Content-Type'] = 'application/json';
        body = JSON.stringify(json);
      } else if (form !== undefined) {
        body = form;
      }
      let res;
      try {
        res = await fetch(path, { method, headers, body, cache: 'no-store' });
      } catch {
        throw new ApiError(0, 'The service cannot be reached.');
      }
      if (res.status === 401) {
        if (method === 'GET') this.viewNeedsToken = true;
        const had = this.token;
        if (had) this.token = '';
        const why = had ? 'The token was not accepted.' : 'This service requires an access token.';
        if (await this.obtainToken(why)) continue;
        throw new ApiError(401, 'An access token is required.');
      }
      if (!res.ok) throw new ApiError(res.status, await errorMessage(res));
      if (res.status === 204) return null;
      const type = res.headers.get('Content-Type') || '';
      return type.includes('json') ? res.json() : res.text();
    }
  }

  get(path) {
    return this.request('GET', path);
  }

  // -- resources (SPEC §6) -----------------------------------------------------------------------
  async worlds() {
    return listOf(await this.get('/api/worlds'), 'worlds');
  }

  uploadWorld(file) {
    const form = new FormData();
    form.append('file', file, file.name);
    return this.request('POST', '/api/worlds', { form });
  }

  config() {
    return this.get('/api/config');
  }

  async runs() {
    return listOf(await this.get('/api/runs'), 'runs');
  }

  run(id) {
    return this.get(`/api/runs/${encodeURIComponent(id)}`);
  }

  startRun(params) {
    return this.request('POST', '/api/runs', { json: params });
  }

  setSpeed(id, speed) {
    return this.request('PATCH', `/api/runs/${encodeURIComponent(id)}`, { json: { speed } });
  }

  stopRun(id) {
    return this.request('POST', `/api/runs/${encodeURIComponent(id)}/stop`);
  }

  deleteRun(id) {
    return this.request('DELETE', `/api/runs/${encodeURIComponent(id)}`);
  }

  fileUrl(id, name) {
    return `/api/runs/${encodeURIComponent(id)}/${name}`;
  }

  /** Fetch a download with the token header and hand it to the browser as a file. */
  async download(url, filename) {
    for (;;) {
      let res;
      try {
        res = await fetch(url, { headers: this.authHeaders(), cache: 'no-store' });
      } catch {
        throw new ApiError(0, 'The service cannot be reached.');
      }
      if (res.status === 401) {
        this.viewNeedsToken = true;
        if (await this.obtainToken('This download requires an access token.')) continue;
      }
      if (!res.ok) throw new ApiError(res.status, await errorMessage(res));
      const blob = await res.blob();
      const href = URL.createObjectURL(blob);
      const a = document.createElement('a');
      a.href = href;
      a.download = filename;
      a.hidden = true;
      document.body.append(a);
      a.click();
      a.remove();
      setTimeout(() => URL.revokeObjectURL(href), 60_000);
      return;
    }
  }
}

/** Lists may come bare or wrapped (`{"runs": [...]}`); accept both. */
function listOf(body, key) {
  if (Array.isArray(body)) return body;
  if (body && Array.isArray(body[key])) return body[key];
  if (body && Array.isArray(body.items)) return body.items;
  return [];
}

/** A token passed in the page URL (`?token=...`, as the server prints it) is kept for the session
 * and removed from the address bar so it does not linger in history or screenshots. */
export function adoptTokenFromUrl(api) {
  const url = new URL(window.location.href);
  const token = url.searchParams.get('token');
  if (!token) return;
  api.token = token;
  api.viewNeedsToken = true; // it was already in a URL, so the socket's URL reveals nothing new
  url.searchParams.delete('token');
  window.history.replaceState(null, '', url.pathname + url.search + url.hash);
}
