// @ts-check
// The daemon's REST API and event stream, as the page uses them.
//
// Every URL is relative to the page, so the panel also works behind a reverse proxy
// that serves the daemon under a sub-path.

/** @import { DaemonEvent } from '../types/daemon' */

/**
 * An answer of the API: its status, and its body parsed from JSON (null when empty; the
 * shape is the endpoint's, docs/api.md).
 * @typedef {{status: number, ok: boolean, body: any}} Answer
 */

const TOKEN_KEY = 'bwsd.token';

// ----- the operator's token -----
//
// Kept in the tab's session storage, so it ends with the browser session; "remember me"
// keeps it in local storage instead, for the next sessions too. Only one of the two
// holds it at a time.

/**
 * @param {'local' | 'session'} kind
 * @returns {Storage | null}
 */
function store(kind) {
  try {
    return kind === 'local' ? window.localStorage : window.sessionStorage;
  } catch {
    return null; // storage disabled: the page still works for open reads
  }
}

/** The token kept in this tab or browser, or null. */
export function getToken() {
  try {
    return store('session')?.getItem(TOKEN_KEY) || store('local')?.getItem(TOKEN_KEY) || null;
  } catch {
    return null;
  }
}

/** True when the token is remembered beyond this browser session (local storage). */
export function tokenRemembered() {
  try {
    return Boolean(store('local')?.getItem(TOKEN_KEY));
  } catch {
    return false;
  }
}

/**
 * Keep `token` for this session, or beyond it with `remember` (null or '' forgets it).
 * @param {string | null} token
 * @param {boolean} [remember]
 */
export function setToken(token, remember = false) {
  for (const kind of /** @type {const} */ (['session', 'local'])) {
    try {
      const place = store(kind);
      if (!place) continue;
      if (token && (kind === 'local') === remember) place.setItem(TOKEN_KEY, token);
      else place.removeItem(TOKEN_KEY);
    } catch {
      // storage disabled or full: nothing to keep
    }
  }
}

/**
 * A link such as `…/#token=XYZ` hands the page a token: keep it for this session, then
 * take it out of the address bar (and so out of the history) at once.
 */
export function takeTokenFromFragment() {
  const fragment = new URLSearchParams(location.hash.replace(/^#/, ''));
  const token = fragment.get('token');
  if (token === null) return null;
  fragment.delete('token');
  const rest = fragment.toString();
  history.replaceState(history.state, '', location.pathname + location.search + (rest ? `#${rest}` : ''));
  if (token) setToken(token, false);
  return token || null;
}

// ----- REST -----

const REQUEST_MS = 10000; // a request not answered by then counts as the daemon not answering

/**
 * One request to the API: `{status, body}`, body the parsed JSON answer (or null).
 * HTTP errors are answers, not exceptions: the caller shows a 409's `error` to the
 * operator. Only a network failure, or no answer within `timeoutMs`, throws.
 * @param {string} path
 * @param {{method?: string, body?: unknown, timeoutMs?: number}} [options]
 * @returns {Promise<Answer>}
 */
export async function request(path, { method = 'GET', body, timeoutMs = REQUEST_MS } = {}) {
  /** @type {Record<string, string>} */
  const headers = { Accept: 'application/json' };
  const token = getToken();
  if (token) headers.Authorization = `Bearer ${token}`;
  /** @type {RequestInit} */
  const init = { method, headers, cache: 'no-store' };
  if (timeoutMs) init.signal = AbortSignal.timeout(timeoutMs);
  if (body !== undefined) {
    headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  const response = await fetch(path, init);
  let parsed = null;
  const text = await response.text();
  if (text) {
    try {
      parsed = JSON.parse(text);
    } catch {
      parsed = { error: text.slice(0, 300) };
    }
  }
  return { status: response.status, ok: response.ok, body: parsed };
}

/**
 * GET `path` with the token and save the answer as the file `name` (the browser's download).
 * `{ok, status, error}`; the file is saved only for a 200.
 * @param {string} path
 * @param {string} name
 * @returns {Promise<{ok: boolean, status: number, error: string}>}
 */
export async function download(path, name) {
  /** @type {Record<string, string>} */
  const headers = {};
  const token = getToken();
  if (token) headers.Authorization = `Bearer ${token}`;
  const response = await fetch(path, { headers, cache: 'no-store' });
  if (!response.ok) {
    /** @type {Pick<Answer, 'status' | 'body'>} */
    const answer = { status: response.status, body: null };
    try {
      answer.body = await response.json();
    } catch {
      // not JSON: the status says it
    }
    return { ok: false, status: response.status, error: errorText(answer) };
  }
  const url = URL.createObjectURL(await response.blob());
  const link = document.createElement('a');
  link.href = url;
  link.download = name;
  link.hidden = true;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 60000); // the download has its copy by then
  return { ok: true, status: response.status, error: '' };
}

/**
 * True for the answer to a connection over its address's limit (503 with the limit): the
 * event link says so in its banner, and gets in once a connection is freed.
 * @param {Pick<Answer, 'status' | 'body'>} answer
 */
export function crowdedAnswer(answer) {
  return answer.status === 503 && typeof answer.body?.limit === 'number';
}

/**
 * The `error` of a refused request, with a fallback naming the status.
 * @param {Pick<Answer, 'status' | 'body'>} answer
 */
export function errorText(answer) {
  const error = answer.body && typeof answer.body.error === 'string' ? answer.body.error : '';
  return error || `the daemon answered ${answer.status}`;
}

// ----- the event stream -----

// The token goes in the stream's first message, never in its URL: the browser prints a
// failed socket's URL on its console, and servers and proxies log URLs (docs/api.md).
const SUBPROTOCOL = 'bwsd.auth';
const POLICY = 1008; // the daemon refused the token (unknown, removed, or too low a role)
const TRY_LATER = 1013; // too many connections from this address: the daemon said how many
const FIRST_RETRY_MS = 500;
const LAST_RETRY_MS = 5000;
const CROWDED_FIRST_MS = 1000;
const CROWDED_LAST_MS = 30000;

/**
 * Why the event stream is down, as far as the daemon said: it closed it over too many
 * connections from this address (`crowded`: the limit, and the connections counted), it
 * refused the token (`denied`, with its reason), or nothing was said (`lost`: no daemon,
 * or the connection dropped).
 * @typedef {{kind: 'lost'}
 *   | {kind: 'crowded', limit: number | null, open: number | null, reason: string}
 *   | {kind: 'denied', reason: string, wasUp: boolean}} LinkDown
 */

/**
 * The daemon's event WebSocket, reconnected with a backoff: 0.5 s doubling to 5 s, or 1 s
 * doubling to 30 s while the daemon refuses it for too many connections.
 *
 * `onEvent(message)` gets every parsed event (the `auth` answer too); `onLink(live, why)`
 * is told when the link goes up (once the daemon accepted the token) or down, and why.
 * `start()` connects (again, e.g. with a new token), `stop()` hangs up for good.
 */
export class EventLink {
  /**
   * @param {object} callbacks
   * @param {(event: DaemonEvent) => void} callbacks.onEvent
   * @param {(live: boolean, why: LinkDown | null) => void} callbacks.onLink
   */
  constructor({ onEvent, onLink }) {
    this.onEvent = onEvent;
    this.onLink = onLink;
    /** @type {WebSocket | null} */
    this.socket = null;
    this.retryMs = FIRST_RETRY_MS;
    this.crowdedMs = CROWDED_FIRST_MS;
    /** @type {number | null} when the next attempt starts (ms since the epoch), while down */
    this.retryAt = null;
    /** @type {ReturnType<typeof setTimeout> | undefined} */
    this.timer = undefined;
    this.wanted = false;
  }

  /** The WebSocket address next to the page: ws: or wss: as the page itself. */
  static url() {
    const url = new URL('api/v1/events', location.href);
    url.protocol = location.protocol === 'https:' ? 'wss:' : 'ws:';
    url.hash = '';
    url.search = '';
    return url.href;
  }

  start() {
    this.stop();
    this.wanted = true;
    this.retryMs = FIRST_RETRY_MS;
    this.crowdedMs = CROWDED_FIRST_MS;
    this.connect();
  }

  stop() {
    this.wanted = false;
    clearTimeout(this.timer);
    this.timer = undefined;
    this.retryAt = null;
    if (this.socket) {
      const socket = this.socket;
      this.socket = null;
      socket.onmessage = socket.onclose = socket.onerror = null;
      // Closed while still connecting, the browser warns on its console: close it once open.
      if (socket.readyState === WebSocket.CONNECTING) socket.onopen = () => socket.close();
      else {
        socket.onopen = null;
        socket.close();
      }
    }
    this.onLink(false, null);
  }

  connect() {
    const socket = new WebSocket(EventLink.url(), SUBPROTOCOL);
    this.socket = socket;
    /** @type {{limit?: unknown, open?: unknown} | null} the daemon's `refused` event, if it sent one */
    let refused = null;
    let up = false;
    socket.onopen = () => socket.send(JSON.stringify({ type: 'auth', token: getToken() }));
    socket.onmessage = (message) => {
      let event;
      try {
        event = JSON.parse(message.data);
      } catch {
        return; // not an event of ours
      }
      if (event.event === 'refused') {
        refused = event;
        return;
      }
      if (event.event === 'auth' && !up) {
        up = true; // the daemon took the token: the events follow
        this.retryMs = FIRST_RETRY_MS;
        this.crowdedMs = CROWDED_FIRST_MS;
        this.retryAt = null;
        this.onLink(true, null);
      }
      this.onEvent(event);
    };
    socket.onerror = () => {}; // the close that follows says it all
    socket.onclose = (close) => {
      if (this.socket !== socket) return;
      this.socket = null;
      const why = downWhy(close, refused, up);
      let delay;
      if (why.kind === 'crowded') {
        // Many tabs retrying at once: spread them, so that they do not come back together.
        delay = this.crowdedMs * (0.8 + 0.4 * Math.random());
        this.crowdedMs = Math.min(this.crowdedMs * 2, CROWDED_LAST_MS);
      } else {
        delay = this.retryMs;
        this.retryMs = Math.min(this.retryMs * 2, LAST_RETRY_MS);
      }
      this.retryAt = this.wanted ? Date.now() + delay : null;
      this.onLink(false, why);
      if (!this.wanted) return;
      this.timer = setTimeout(() => this.connect(), delay);
    };
  }
}

/**
 * Why a stream closed, from its close code (and the `refused` event before it).
 * @param {CloseEvent} close
 * @param {{limit?: unknown, open?: unknown} | null} refused
 * @param {boolean} wasUp the daemon had accepted the token
 * @returns {LinkDown}
 */
function downWhy(close, refused, wasUp) {
  if (close.code === TRY_LATER) {
    const limit = typeof refused?.limit === 'number' ? refused.limit : null;
    const open = typeof refused?.open === 'number' ? refused.open : null;
    return { kind: 'crowded', limit, open, reason: close.reason };
  }
  if (close.code === POLICY) return { kind: 'denied', reason: close.reason, wasUp };
  return { kind: 'lost' };
}
