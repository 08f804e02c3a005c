// MapLibre GL JS in a real browser over fmrh's terrain-RGB tiles (tests/maplibre_terrain.rs
// runs it): a page whose map has a `raster-dem` source, as terrain and as a hillshade
// layer, from a TileJSON URL (`fmrh serve`'s /NAME/terrain-rgb.json) or from a PMTiles
// archive read through the `pmtiles` protocol (the archive served here, with range
// requests), loaded in headless Chromium (SwiftShader, driven by playwright-core). Once
// every tile is in, it asks `map.queryTerrainElevation` at each point, then tilts the
// camera over the relief and takes a screenshot. Prints one JSON object: the heights, the
// DEM tile addresses fetched, and every console error, failed request and 4xx/5xx.
//
//   node maplibre-terrain.mjs SOURCE ENCODING TILE_SIZE POINTS.json LON,LAT SCREENSHOT.png
//
// SOURCE is an http(s) TileJSON URL, or a `.pmtiles` file path. POINTS.json is
// [[lon, lat], ...] in degrees, all within the view of a map centred on LON,LAT at zoom 14
// (pitch 0). CHROMIUM names the browser (default /usr/bin/chromium). Exit status 1 with a
// message on standard error when the page fails or the map does not finish loading.
import fs from 'fs';
import path from 'path';
import { fileURLToPath } from 'url';
import { launch, servePage } from './chromium.mjs';

const [source, encoding, tileSizeArg, pointsFile, centreArg, screenshot] = process.argv.slice(2);
if (!screenshot) {
  console.error('usage: node maplibre-terrain.mjs SOURCE ENCODING TILE_SIZE POINTS.json LON,LAT SCREENSHOT.png');
  process.exit(2);
}
const points = JSON.parse(fs.readFileSync(pointsFile, 'utf8'));
const centre = centreArg.split(',').map(Number);
const tileSize = Number(tileSizeArg);
const here = path.dirname(fileURLToPath(import.meta.url));
const archive = /^https?:/.test(source) ? null : source;

const page = `<!doctype html>
<html><head><meta charset="utf-8"><link rel="icon" href="data:,">
<link rel="stylesheet" href="/maplibre/maplibre-gl.css">
<style>html,body,#map{margin:0;width:100%;height:100%;overflow:hidden}</style>
<script src="/pmtiles/pmtiles.js"></script>
<script type="module">import * as maplibregl from '/maplibre/maplibre-gl.mjs'; window.maplibregl = maplibregl; window.dispatchEvent(new Event('maplibre'));</script>
</head><body><div id="map"></div></body></html>`;
const roots = {
  '/maplibre/': path.join(here, 'node_modules/maplibre-gl/dist'),
  '/pmtiles/': path.join(here, 'node_modules/pmtiles/dist'),
};
// Range requests, as a CDN answers them: the pmtiles protocol reads only what it needs.
const serveArchive = (url, req, res) => {
  if (url !== '/archive.pmtiles' || !archive) return false;
  const size = fs.statSync(archive).size;
  const m = /^bytes=(\d+)-(\d*)$/.exec(req.headers.range || '');
  if (!m) {
    res.writeHead(200, { 'Content-Length': size, 'Accept-Ranges': 'bytes' });
    fs.createReadStream(archive).pipe(res);
    return true;
  }
  const start = Number(m[1]);
  const end = Math.min(m[2] ? Number(m[2]) : size - 1, size - 1);
  if (start > end) {
    res.writeHead(416, { 'Content-Range': `bytes */${size}` });
    res.end();
    return true;
  }
  res.writeHead(206, { 'Content-Range': `bytes ${start}-${end}/${size}`, 'Content-Length': end - start + 1, 'Accept-Ranges': 'bytes' });
  fs.createReadStream(archive, { start, end }).pipe(res);
  return true;
};
const { server, origin } = await servePage({ page, roots, extra: serveArchive });
const sourceUrl = archive ? `pmtiles://${origin}/archive.pmtiles` : source;

const browser = await launch();
let status = 0;
try {
  const tab = await browser.newPage({ viewport: { width: 960, height: 600 } });
  const problems = [];
  const fetched = [];
  tab.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  tab.on('console', (m) => { if (m.type() === 'error') problems.push(`console: ${m.text()}`); });
  tab.on('requestfailed', (r) => problems.push(`request failed: ${r.url()} (${r.failure()?.errorText})`));
  tab.on('response', (r) => {
    if (r.status() >= 400) problems.push(`HTTP ${r.status()}: ${r.url()}`);
    const m = /\/terrain-rgb\/(\d+)\/(\d+)\/(\d+)\.png/.exec(r.url());
    if (m) fetched.push(m.slice(1).map(Number));
  });
  await tab.goto(`${origin}/`);
  await tab.waitForFunction(() => window.maplibregl, null, { timeout: 60000 });
  const report = await tab.evaluate(async ({ sourceUrl, encoding, tileSize, points, centre }) => {
   try {
    const maplibregl = window.maplibregl;
    if (sourceUrl.startsWith('pmtiles://')) {
      const protocol = new window.pmtiles.Protocol();
      maplibregl.addProtocol('pmtiles', protocol.tile);
    }
    const map = new maplibregl.Map({
      container: 'map',
      style: {
        version: 8,
        sources: { dem: { type: 'raster-dem', url: sourceUrl, encoding, tileSize } },
        layers: [
          { id: 'ground', type: 'background', paint: { 'background-color': '#efe9dc' } },
          {
            id: 'relief',
            type: 'color-relief',
            source: 'dem',
            paint: {
              'color-relief-color': ['interpolate', ['linear'], ['elevation'],
                0, '#4f7f52', 300, '#9fb069', 700, '#cdb57f', 1200, '#b08a63', 1800, '#efe9e0'],
            },
          },
          {
            id: 'hillshade',
            type: 'hillshade',
            source: 'dem',
            paint: {
              'hillshade-shadow-color': '#3d3a33',
              'hillshade-highlight-color': '#fffdf6',
              'hillshade-accent-color': '#6b6453',
              'hillshade-exaggeration': 0.6,
            },
          },
        ],
        terrain: { source: 'dem', exaggeration: 1 },
      },
      center: centre,
      zoom: 14,
      pitch: 0,
      interactive: false,
      fadeDuration: 0,
      attributionControl: false,
      canvasContextAttributes: { preserveDrawingBuffer: true },
    });
    const settled = () => new Promise((resolve, reject) => {
      const started = performance.now();
      const check = () => {
        if (map.loaded() && map.areTilesLoaded() && !map.isMoving()) {
          // Twice, a frame apart: idle, and still idle.
          requestAnimationFrame(() => requestAnimationFrame(() => (map.areTilesLoaded() ? resolve() : setTimeout(check, 100))));
          return;
        }
        if (performance.now() - started > 180000) {
          reject(new Error('the map did not finish loading in 180 s'));
          return;
        }
        setTimeout(check, 100);
      };
      map.once('error', (e) => reject(new Error(`map error: ${e.error && e.error.message}`)));
      check();
    });
    await settled();
    const heights = points.map((p) => map.queryTerrainElevation(p));
    // The screenshot: the hills north-east of the points, from the south-west, tilted.
    map.jumpTo({ center: [centre[0] + 0.2, centre[1] + 0.22], zoom: 10.3, pitch: 60, bearing: 20 });
    await settled();
    window.fmrhMap = map;
    return { heights };
   } catch (e) {
    return { failed: `${e && e.name}: ${e && e.message}\n${e && e.stack}` };
   }
  }, { sourceUrl, encoding, tileSize, points, centre });
  if (report.failed) throw new Error(`in the page: ${report.failed}`);
  await tab.screenshot({ path: screenshot });
  console.log(JSON.stringify({ ...report, fetched, problems }));
} catch (e) {
  console.error(String(e && e.stack ? e.stack : e));
  status = 1;
} finally {
  await browser.close();
  server.close();
}
process.exit(status);
