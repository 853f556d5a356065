// @ts-check
// Who is logged in: the token (api.js keeps it), its holder and role as `/whoami` names
// them, the login form with "remember me", log out, and a `#token=` link opened in a tab
// that shows the page already.

import { getToken, request, setToken, takeTokenFromFragment, tokenRemembered } from './api.js';

/** @import { Answer } from './api.js' */

import { byId as $ } from './dom.js';
const COMMANDING_ROLES = new Set(['operator', 'admin']);

export class Session {
  /**
   * @param {object} callbacks
   * @param {(token: string, remember: boolean) => void} callbacks.onLogIn called with a token
   *   to log in with, and whether to remember it
   * @param {() => void} callbacks.onLogOut called when the operator logs out
   */
  constructor({ onLogIn, onLogOut }) {
    /** @type {string | null} the token's holder, from /whoami */
    this.name = null;
    /** @type {string | null} its role (null: not known yet) */
    this.role = null;
    $('login').addEventListener('submit', (event) => {
      event.preventDefault();
      const input = $('token-input', HTMLInputElement);
      const token = input.value.trim();
      if (!token) return;
      input.value = '';
      onLogIn(token, $('remember', HTMLInputElement).checked);
    });
    $('logout').addEventListener('click', () => onLogOut());
    window.addEventListener('hashchange', () => {
      const token = takeTokenFromFragment();
      if (token) onLogIn(token, false);
    });
  }

  /** The token's role may command the machine and load programs. */
  mayCommand() {
    return Boolean(getToken()) && this.role !== null && COMMANDING_ROLES.has(this.role);
  }

  /** The token's role may change the unit mode (admin, as on every door of the daemon). */
  mayChangeMode() {
    return Boolean(getToken()) && this.role === 'admin';
  }

  /**
   * Keep `token` (for the session, or beyond with `remember`); its role is not known yet.
   * @param {string} token
   * @param {boolean} remember
   */
  keep(token, remember) {
    setToken(token, remember);
    this.name = this.role = null;
  }

  /** Forget the token and who held it. */
  end() {
    setToken(null);
    this.name = this.role = null;
  }

  /** Ask the daemon whose token this is (an open read without one: anonymous viewer). */
  async readRole() {
    const answer = await request('api/v1/whoami');
    if (answer.ok) {
      this.name = answer.body.name;
      this.role = answer.body.role;
    }
    return answer;
  }

  /**
   * A 403 names the role the token holds.
   * @param {Answer} answer
   */
  noteRefusal(answer) {
    if (typeof answer.body?.role === 'string') this.role = answer.body.role;
  }

  /** The login form or the session line, and the read-only note. */
  draw() {
    const token = getToken();
    $('login').hidden = Boolean(token);
    $('session').hidden = !token;
    $('remember', HTMLInputElement).checked = tokenRemembered();
    const who = this.name ? `${this.name}, ` : '';
    $('session-role').textContent = this.role ? `logged in (${who}${this.role})` : 'logged in';
    const readOnly = $('read-only');
    readOnly.hidden = !this.role || COMMANDING_ROLES.has(this.role);
    readOnly.textContent = token
      ? `read only: a ${this.role}'s token may not command the machine or load programs`
      : 'read only: log in with an operator token to command the machine';
  }
}
