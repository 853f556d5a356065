// The page's hooks for tests and diagnostics (docs/preview.md): `window.bwsd`.
interface Window {
  bwsd?: object;
}
