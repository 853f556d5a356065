// @ts-check
// The message line of the Control panel: what the daemon answered or refused, or why
// nothing was sent. A success fades after a while, an error stays.

let timer = null;

/** Show `text`; `kind`: 'ok', 'error', 'pending' or '' (plain). */
export function say(text, kind) {
  const message = document.getElementById('message');
  message.textContent = text;
  message.dataset.kind = kind;
  clearTimeout(timer);
  if (kind === 'ok') timer = setTimeout(() => say('', ''), 8000);
}

/** True while the line says the daemon cannot be reached (cleared when it answers again). */
export function saysUnreachable() {
  const message = document.getElementById('message');
  return message.dataset.kind === 'error' && message.textContent.includes('cannot be reached');
}
