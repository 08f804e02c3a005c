// Drives fmrh's viewer in headless Chromium (tests/viewer.rs runs it): loads the page,
// waits for the first scene, takes a screenshot, then flies forward, moves the tolerance
// slider and picks TINs within 5 m, and prints what the page showed after each step as JSON
// on standard output.
//
//   node viewer-check.mjs URL SCREENSHOT.png
//
// CHROMIUM names the browser (default /usr/bin/chromium). Exit status 1 with a message on
// standard error when the page fails or a step times out.
import { launch } from './chromium.mjs';

const [url, screenshot] = process.argv.slice(2);
if (!url || !screenshot) {
  console.error('usage: node viewer-check.mjs URL SCREENSHOT.png');
  process.exit(2);
}

const browser = await launch();
let status = 0;
try {
  const page = await browser.newPage({ viewport: { width: 960, height: 600 } });
  const problems = [];
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console: ${m.text()}`); });
  await page.goto(url);

  // Waits until the page has drawn more than `scenes` scenes and asks for no other.
  const settled = async (scenes) => {
    await page.waitForFunction(
      (n) => window.fmrhViewer && (window.fmrhViewer.state === 'error'
        || (window.fmrhViewer.scenes > n && !window.fmrhViewer.busy)),
      scenes,
      { timeout: 120000, polling: 100 },
    );
    // Two more animation frames: the last scene is on the canvas.
    await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
    const snapshot = await page.evaluate(() => {
      const v = window.fmrhViewer;
      const shown = {};
      for (const td of document.querySelectorAll('[data-stat]')) shown[td.dataset.stat] = td.textContent;
      return { state: v.state, error: v.error, scenes: v.scenes, query: v.query, stats: v.stats, triangles: v.triangles, shown };
    });
    if (snapshot.state === 'error') throw new Error(`the viewer failed: ${snapshot.error}`);
    return snapshot;
  };

  const first = await settled(0);
  await page.screenshot({ path: screenshot });
  const renderer = await page.evaluate(() => window.fmrhViewer.renderer);

  // Fly forward (W held), as a user would: the page asks for scenes as the camera moves.
  // W stays down until the page has flown at least 50 m (frames are slow on a CPU).
  await page.mouse.click(480, 580);
  const from = await page.evaluate(() => window.fmrhViewer.eye);
  await page.keyboard.down('w');
  await page.waitForFunction(
    (e) => Math.hypot(window.fmrhViewer.eye[0] - e[0], window.fmrhViewer.eye[1] - e[1]) > 50,
    from,
    { timeout: 60000, polling: 50 },
  );
  await page.keyboard.up('w');
  const moved = await settled(first.scenes);

  // The tolerance slider, to 4 px.
  await page.evaluate(() => {
    const tau = document.getElementById('tau');
    tau.value = '4';
    tau.dispatchEvent(new Event('input'));
  });
  const tau4 = await settled(moved.scenes);

  // The mesh select, to TINs within 5 m.
  await page.selectOption('#tin', '5');
  const tin = await settled(tau4.scenes);

  if (problems.length) throw new Error(problems.join('\n'));
  console.log(JSON.stringify({ renderer, first, moved, tau4, tin }));
} catch (e) {
  console.error(String(e && e.stack ? e.stack : e));
  status = 1;
} finally {
  await browser.close();
}
process.exit(status);
