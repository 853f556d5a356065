// The daemon's REST API and event stream, as the page uses them.
//
// Every URL is relative to the page, so the panel also works behind a reverse proxy
// that serves the daemon under a sub-path.

const TOKEN_KEY = 'bwsd.token';

// ----- the operator's token -----

/** The token kept in this browser, or null. */
export function getToken() {
  try {
    return localStorage.getItem(TOKEN_KEY) || null;
  } catch {
    return null; // storage disabled: the page still works for open reads
  }
}

/** Keep `token` (or forget it, for null / ''). */
export function setToken(token) {
  try {
    if (token) localStorage.setItem(TOKEN_KEY, token);
    else localStorage.removeItem(TOKEN_KEY);
  } catch {
    // storage disabled: nothing to keep
  }
}

/**
 * A link such as `…/#token=XYZ` hands the page a token: keep it, then take it out of
 * the address bar (and so out of the history) at once.
 */
export function takeTokenFromFragment() {
  const fragment = new URLSearchParams(location.hash.replace(/^#/, ''));
  const token = fragment.get('token');
  if (token === null) return null;
  fragment.delete('token');
  const rest = fragment.toString();
  history.replaceState(history.state, '', location.pathname + location.search + (rest ? `#${rest}` : ''));
  if (token) setToken(token);
  return token || null;
}

// ----- REST -----

/**
 * One request to the API: `{status, body}`, body the parsed JSON answer (or null).
 * HTTP errors are answers, not exceptions: the caller shows a 409's `error` to the
 * operator. Only a network failure throws.
 */
export async function request(path, { method = 'GET', body, signal } = {}) {
  const headers = { Accept: 'application/json' };
  const token = getToken();
  if (token) headers.Authorization = `Bearer ${token}`;
  const init = { method, headers, signal, cache: 'no-store' };
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

/** The `error` of a refused request, with a fallback naming the status. */
export function errorText(answer) {
  const error = answer.body && typeof answer.body.error === 'string' ? answer.body.error : '';
  return error || `the daemon answered ${answer.status}`;
}

// ----- the event stream -----

const FIRST_RETRY_MS = 500;
const LAST_RETRY_MS = 5000;

/**
 * The daemon's event WebSocket, reconnected with a backoff (0.5 s doubling to 5 s).
 *
 * `onEvent(message)` gets every parsed event; `onLink(live)` is told when the link goes
 * up or down. `start()` connects (again, e.g. with a new token), `stop()` hangs up for good.
 */
export class EventLink {
  constructor({ onEvent, onLink }) {
    this.onEvent = onEvent;
    this.onLink = onLink;
    this.socket = null;
    this.retryMs = FIRST_RETRY_MS;
    this.timer = null;
    this.wanted = false;
  }

  /** The WebSocket address next to the page: ws: or wss: as the page itself. */
  static url() {
    const url = new URL('api/v1/events', location.href);
    url.protocol = location.protocol === 'https:' ? 'wss:' : 'ws:';
    url.hash = '';
    const token = getToken();
    if (token) url.searchParams.set('token', token);
    return url.href;
  }

  start() {
    this.stop();
    this.wanted = true;
    this.retryMs = FIRST_RETRY_MS;
    this.connect();
  }

  stop() {
    this.wanted = false;
    clearTimeout(this.timer);
    this.timer = null;
    if (this.socket) {
      const socket = this.socket;
      this.socket = null;
      socket.onopen = socket.onmessage = socket.onclose = socket.onerror = null;
      socket.close();
    }
    this.onLink(false);
  }

  connect() {
    const socket = new WebSocket(EventLink.url());
    this.socket = socket;
    socket.onopen = () => {
      this.retryMs = FIRST_RETRY_MS;
      this.onLink(true);
    };
    socket.onmessage = (message) => {
      let event;
      try {
        event = JSON.parse(message.data);
      } catch {
        return; // not an event of ours
      }
      this.onEvent(event);
    };
    socket.onerror = () => {}; // the close that follows says it all
    socket.onclose = () => {
      if (this.socket !== socket) return;
      this.socket = null;
      this.onLink(false);
      if (!this.wanted) return;
      this.timer = setTimeout(() => this.connect(), this.retryMs);
      this.retryMs = Math.min(this.retryMs * 2, LAST_RETRY_MS);
    };
  }
}
