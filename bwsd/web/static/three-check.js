// @ts-check
// Says so on the page when three.js is not installed beside it (`npm ci` was not run before
// bwsd was built or installed, docs/preview.md): without it the page's scripts cannot load,
// and the page would stay blank. It imports nothing, so it runs whatever is missing.

const THREE_URL = './vendor/three/build/three.module.js';

async function checkThree() {
  let answer;
  try {
    answer = await fetch(THREE_URL, { method: 'HEAD', cache: 'no-store' });
  } catch {
    return; // the daemon does not answer: the page's own link state says so
  }
  if (answer.status !== 404) return;
  const banner = document.getElementById('page-banner');
  if (!banner) return;
  banner.textContent =
    'three.js is missing from this installation of bwsd, so the page cannot draw the preform ' +
    'or run. Install it where bwsd was built (npm ci --prefix bwsd/web) and reinstall bwsd, ' +
    'or point [api] web_root at a page folder that has node_modules/three (docs/preview.md).';
  banner.hidden = false;
}

checkThree();
