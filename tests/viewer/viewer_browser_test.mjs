// Opens a viewer.html written by `cvd view` in headless Chromium (Debian's, driven by
// playwright-core) and checks what a user would see: the page loads with no console error or
// uncaught exception, the 3-D canvas renders non-blank pixels, the slider (moved with the
// keyboard, as a user would) changes the frame shown, and dragging orbits the view.
//
//   node viewer_browser_test.mjs PAGE.html [SCREENSHOT.png]
// Exit 0 = passed, 1 = failed (each failure printed), 77 = skipped (says why).
import { existsSync } from 'node:fs';
import { createRequire } from 'node:module';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const require = createRequire(path.join(here, '../../tools/viewer/web/package.json'));
const [page_file, screenshot] = process.argv.slice(2);
const chromiumPath = process.env.CVD_CHROMIUM || '/usr/bin/chromium';

function skip(why) {
  console.log(`skipped: ${why}`);
  process.exit(77);
}
if (!page_file || !existsSync(page_file)) {
  console.error(`viewer_browser_test: page '${page_file}' not found`);
  process.exit(1);
}
if (!existsSync(chromiumPath)) skip(`no Chromium at ${chromiumPath} (apt install chromium)`);
let chromium;
try {
  ({ chromium } = require('playwright-core'));
} catch {
  skip('playwright-core is not installed (npm ci --prefix tools/viewer/web)');
}

const failures = [];
const check = (ok, what) => {
  if (!ok) failures.push(what);
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
};

const browser = await chromium.launch({
  executablePath: chromiumPath,
  // WebGL on the CPU (SwiftShader); no network, no background services.
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
         '--disable-background-networking', '--disable-component-update', '--disable-sync',
         '--disable-quic', '--no-first-run'],
});
try {
  const context = await browser.newContext({ viewport: { width: 1280, height: 860 } });
  // The page must not need the network: every request but the page itself fails the test.
  const requests = [];
  await context.route('**/*', (route) => {
    const url = route.request().url();
    if (url.startsWith('file:') || url.startsWith('data:')) return route.continue();
    requests.push(url);
    return route.abort();
  });
  const page = await context.newPage();
  const errors = [];
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  page.on('pageerror', (e) => errors.push(String(e)));
  await page.goto(pathToFileURL(path.resolve(page_file)).href);
  await page.waitForFunction(() => window.cvdViewer && window.cvdViewer.ready, null,
                             { timeout: 60000 });

  // Non-blank: pixels of the WebGL canvas that differ from the background colour.
  const lit = () => page.evaluate(() => {
    const gl = document.querySelector('#view canvas');
    const c = document.createElement('canvas');
    c.width = gl.width;
    c.height = gl.height;
    const ctx = c.getContext('2d');
    ctx.drawImage(gl, 0, 0);
    const d = ctx.getImageData(0, 0, c.width, c.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4)
      if (Math.abs(d[i] - 0x15) + Math.abs(d[i + 1] - 0x17) + Math.abs(d[i + 2] - 0x1c) > 24) ++n;
    return { lit: n, total: c.width * c.height };
  });
  const before = await lit();
  check(before.total > 100000, `the 3-D canvas has a size (${before.total} px)`);
  check(before.lit > 0.01 * before.total,
        `the canvas renders the cloud: ${before.lit} of ${before.total} px differ from the background`);

  const frameCount = await page.evaluate(() => Number(document.getElementById('slider').max) + 1);
  const label0 = await page.textContent('#frame-label');
  const src0 = await page.getAttribute('#depth', 'src');
  check(frameCount >= 2, `the slider has frames (${frameCount})`);
  await page.focus('#slider');
  await page.keyboard.press('ArrowRight');
  await page.keyboard.press('ArrowRight');
  const label1 = await page.textContent('#frame-label');
  const src1 = await page.getAttribute('#depth', 'src');
  const frame1 = await page.evaluate(() => window.cvdViewer.frame);
  check(frame1 === Math.min(2, frameCount - 1), `the slider moved to frame ${frame1}`);
  check(label1 !== label0, `the frame label changed ('${label0}' -> '${label1}')`);
  check(src1 !== src0, 'the depth image changed');
  const loaded = await page.evaluate(() =>
    ['input', 'depth'].every((id) => {
      const img = document.getElementById(id);
      return img.complete && img.naturalWidth > 0;
    }));
  check(loaded, 'the input and depth images decode');

  // Orbit: a drag over the canvas re-renders a different view.
  const rendersBefore = await page.evaluate(() => window.cvdViewer.renders());
  const box = await page.locator('#view canvas').boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 150, box.y + box.height / 2 + 40, { steps: 8 });
  await page.mouse.up();
  const rendersAfter = await page.evaluate(() => window.cvdViewer.renders());
  check(rendersAfter > rendersBefore, `dragging re-renders the view (${rendersAfter - rendersBefore} frames)`);
  const after = await lit();
  check(after.lit > 0.01 * after.total, `the orbited view still shows the cloud (${after.lit} px)`);

  if (screenshot) {
    // The README's picture: back to the first frame and the start view.
    await page.evaluate(() => window.cvdViewer.setFrame(0));
    await page.screenshot({ path: screenshot });
  }
  check(errors.length === 0, `no console errors or exceptions${errors.length ? ': ' + errors.join(' | ') : ''}`);
  check(requests.length === 0, `no network requests${requests.length ? ': ' + requests.join(', ') : ''}`);
} finally {
  await browser.close();
}
if (failures.length) {
  console.error(`viewer_browser_test: ${failures.length} check(s) failed`);
  process.exit(1);
}
console.log('viewer_browser_test: passed');
