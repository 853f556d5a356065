// @ts-check
// The page's elements by id, checked to be of the kind the scripts use them as.

/**
 * The element `#id`, a `kind` (an HTMLElement unless said). A missing element or one of
 * another kind throws: the page's HTML and its scripts disagree.
 * @overload
 * @param {string} id
 * @returns {HTMLElement}
 */
/**
 * @template {Element} T
 * @overload
 * @param {string} id
 * @param {new (...args: any[]) => T} kind
 * @returns {T}
 */
/**
 * @param {string} id
 * @param {new (...args: any[]) => Element} [kind]
 * @returns {Element}
 */
export function byId(id, kind = HTMLElement) {
  const element = optionalById(id, kind);
  if (element === null) throw new Error(`the page has no element #${id}`);
  return element;
}

/**
 * The element `#id`, a `kind` (an HTMLElement unless said), or null when the page has none.
 * @overload
 * @param {string} id
 * @returns {HTMLElement | null}
 */
/**
 * @template {Element} T
 * @overload
 * @param {string} id
 * @param {new (...args: any[]) => T} kind
 * @returns {T | null}
 */
/**
 * @param {string} id
 * @param {new (...args: any[]) => Element} [kind]
 * @returns {Element | null}
 */
export function optionalById(id, kind = HTMLElement) {
  const element = document.getElementById(id);
  if (element === null) return null;
  if (!(element instanceof kind)) throw new Error(`#${id} is not a ${kind.name}`);
  return element;
}
