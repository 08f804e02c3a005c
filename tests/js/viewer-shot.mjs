// Takes one picture with fmrh's viewer in headless Chromium (tests/viewer.rs runs it): loads
// the page, waits until its first scene is drawn, saves a screenshot and prints, as JSON on
// standard output, where the page's own transformation puts each point given (fmrh's frame,
// metres) on the canvas, in CSS pixels from its top-left.
//
//   node viewer-shot.mjs URL SCREENSHOT.png '[[x,y,z], ...]'
//
// CHROMIUM names the browser (default /usr/bin/chromium). Exit status 1 with a message on
// standard error when the page fails or times out.
import { launch } from './chromium.mjs';

const [url, screenshot, pointsJson] = process.argv.slice(2);
if (!url || !screenshot) {
  console.error("usage: node viewer-shot.mjs URL SCREENSHOT.png '[[x,y,z], ...]'");
  process.exit(2);
}
const points = JSON.parse(pointsJson || '[]');

const browser = await launch();
let status = 0;
try {
  const page = await browser.newPage({ viewport: { width: 960, height: 600 } });
  const problems = [];
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console: ${m.text()}`); });
  await page.goto(url);
  await page.waitForFunction(
    () => window.fmrhViewer && (window.fmrhViewer.state === 'error'
      || (window.fmrhViewer.scenes > 0 && !window.fmrhViewer.busy)),
    null,
    { timeout: 120000, polling: 100 },
  );
  // Two more animation frames: the scene is on the canvas.
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  const report = await page.evaluate((ps) => {
    const v = window.fmrhViewer;
    return { state: v.state, error: v.error, eye: v.eye, projected: ps.map((p) => v.project(p)) };
  }, points);
  if (report.state === 'error') throw new Error(`the viewer failed: ${report.error}`);
  await page.screenshot({ path: screenshot });
  if (problems.length) throw new Error(problems.join('\n'));
  console.log(JSON.stringify(report));
} catch (e) {
  console.error(String(e && e.stack ? e.stack : e));
  status = 1;
} finally {
  await browser.close();
}
process.exit(status);
