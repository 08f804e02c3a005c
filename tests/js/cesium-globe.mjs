// CesiumJS in a real browser over the terrain `fmrh serve` cuts live (tests/cesium_globe.rs
// runs it): @cesium/engine bundled for the browser by esbuild, a page with a CesiumWidget
// whose terrain is `CesiumTerrainProvider.fromUrl(LAYER_URL)` (normals and metadata asked,
// no imagery: the machine's network is closed), loaded in headless Chromium (SwiftShader,
// driven by playwright-core). It waits until the globe has loaded every tile the camera
// needs, takes a screenshot, then asks `sampleTerrainMostDetailed` in the page for each
// point, and prints one JSON object: the heights, the level each came from, the WebGL
// renderer, how many tiles the globe drew, and every console error and failed request.
//
//   node cesium-globe.mjs LAYER_URL POINTS.json CAMERA SCREENSHOT.png
//
// POINTS.json is [[lon, lat], ...] in degrees; CAMERA is `lon,lat,height,heading,pitch`
// (degrees, metres above the ellipsoid). CHROMIUM names the browser (default
// /usr/bin/chromium). Exit status 1 with a message on standard error when the page fails or
// the globe does not finish loading.
import fs from 'fs';
import os from 'os';
import path from 'path';
import { fileURLToPath } from 'url';
import * as esbuild from 'esbuild';
import { launch, servePage } from './chromium.mjs';

const [layerUrl, pointsFile, cameraArg, screenshot] = process.argv.slice(2);
if (!layerUrl || !pointsFile || !cameraArg || !screenshot) {
  console.error('usage: node cesium-globe.mjs LAYER_URL POINTS.json CAMERA SCREENSHOT.png');
  process.exit(2);
}
const points = JSON.parse(fs.readFileSync(pointsFile, 'utf8'));
const camera = cameraArg.split(',').map(Number);
const here = path.dirname(fileURLToPath(import.meta.url));
const engine = path.join(here, 'node_modules/@cesium/engine');

// The engine as one browser script: its ES modules and their CommonJS dependencies, which
// a browser cannot import by name. Workers, assets and third-party files stay as the
// package ships them and are served beside it (CESIUM_BASE_URL).
const scratch = fs.mkdtempSync(path.join(os.tmpdir(), 'fmrh-cesium-'));
const bundle = path.join(scratch, 'cesium.js');
await esbuild.build({
  stdin: {
    contents: "import * as Cesium from '@cesium/engine'; window.Cesium = Cesium;",
    resolveDir: here,
  },
  bundle: true,
  format: 'iife',
  outfile: bundle,
  logLevel: 'error',
});

const page = `<!doctype html>
<html><head><meta charset="utf-8"><link rel="icon" href="data:,">
<style>html,body,#globe,.cesium-widget,.cesium-widget canvas{margin:0;width:100%;height:100%;overflow:hidden;display:block}
.cesium-widget-credits{position:absolute;left:4px;bottom:4px}</style>
<script>window.CESIUM_BASE_URL = '/cesium/';</script>
<script src="/cesium.js"></script></head>
<body><div id="globe"></div></body></html>`;
const roots = {
  '/cesium/Workers/': path.join(engine, 'Build/Workers'),
  '/cesium/ThirdParty/': path.join(engine, 'Build/ThirdParty'),
  '/cesium/Assets/': path.join(engine, 'Source/Assets'),
};
const { server, origin } = await servePage({ page, files: { '/cesium.js': bundle }, roots });

const browser = await launch();
let status = 0;
try {
  const tab = await browser.newPage({ viewport: { width: 960, height: 600 } });
  const problems = [];
  tab.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  tab.on('console', (m) => { if (m.type() === 'error') problems.push(`console: ${m.text()}`); });
  tab.on('requestfailed', (r) => problems.push(`request failed: ${r.url()} (${r.failure()?.errorText})`));
  tab.on('response', (r) => { if (r.status() >= 400) problems.push(`HTTP ${r.status()}: ${r.url()}`); });
  await tab.goto(`${origin}/`);
  const report = await tab.evaluate(async ({ layerUrl, points, camera }) => {
   try {
    const C = window.Cesium;
    const provider = await C.CesiumTerrainProvider.fromUrl(layerUrl, {
      requestVertexNormals: true,
      requestMetadata: true,
    });
    const widget = new C.CesiumWidget('globe', {
      terrainProvider: provider,
      baseLayer: false,
      skyBox: false,
      requestRenderMode: false,
    });
    const globe = widget.scene.globe;
    globe.baseColor = C.Color.fromCssColorString('#d8d2c0');
    // Shade by the sun and colour by height, so the relief shows without imagery.
    globe.enableLighting = true;
    // From the north-west and 40 degrees up, as a hillshade lights: travelling south-east
    // and down, in the east-north-up frame at the camera's longitude and latitude.
    const enu = C.Transforms.eastNorthUpToFixedFrame(C.Cartesian3.fromDegrees(camera[0], camera[1]));
    const local = new C.Cartesian3(0.54, -0.54, -0.64);
    widget.scene.light = new C.DirectionalLight({
      direction: C.Cartesian3.normalize(C.Matrix4.multiplyByPointAsVector(enu, local, new C.Cartesian3()), new C.Cartesian3()),
      intensity: 2.5,
    });
    globe.material = C.Material.fromType('ElevationRamp', {
      image: (() => {
        const c = document.createElement('canvas');
        c.width = 256;
        c.height = 1;
        const g = c.getContext('2d');
        const ramp = g.createLinearGradient(0, 0, 256, 0);
        [[0, '#3c6e47'], [0.35, '#9aa85a'], [0.65, '#b8946a'], [1, '#f4f1ea']].forEach(([t, col]) => ramp.addColorStop(t, col));
        g.fillStyle = ramp;
        g.fillRect(0, 0, 256, 1);
        return c;
      })(),
      minimumHeight: 0,
      maximumHeight: 2000,
    });
    const [lon, lat, h, heading, pitch] = camera;
    widget.camera.setView({
      destination: C.Cartesian3.fromDegrees(lon, lat, h),
      orientation: { heading: C.Math.toRadians(heading), pitch: C.Math.toRadians(pitch), roll: 0 },
    });
    // Loaded: every tile the view needs is in and drawn, for a second of frames.
    let drawn = 0;
    await new Promise((resolve, reject) => {
      const started = performance.now();
      let since = null;
      const check = () => {
        const loaded = globe.tilesLoaded;
        if (loaded && since === null) since = performance.now();
        if (!loaded) since = null;
        if (since !== null && performance.now() - since > 1000) {
          resolve();
          return;
        }
        if (performance.now() - started > 240000) {
          reject(new Error('the globe did not finish loading in 240 s'));
          return;
        }
        setTimeout(check, 100);
      };
      check();
    });
    const surface = globe._surface;
    drawn = surface && surface._tilesToRender ? surface._tilesToRender.length : 0;
    const gl = widget.scene.context._gl;
    const info = gl.getExtension('WEBGL_debug_renderer_info');
    const renderer = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    window.fmrhGlobe = { widget, provider };
    return { renderer, drawn, hasVertexNormals: provider.hasVertexNormals, hasMetadata: provider.hasMetadata };
   } catch (e) {
    return { failed: `${e && e.name}: ${e && e.message}\n${e && e.stack}` };
   }
  }, { layerUrl, points, camera });
  if (report.failed) throw new Error(`in the page: ${report.failed}`);
  await tab.screenshot({ path: screenshot });
  const sampled = await tab.evaluate(async (points) => {
    const C = window.Cesium;
    const { provider } = window.fmrhGlobe;
    const carto = points.map(([lon, lat]) => C.Cartographic.fromDegrees(lon, lat));
    const out = await C.sampleTerrainMostDetailed(provider, carto.map((c) => c.clone()));
    const levels = carto.map((c) => provider.availability.computeMaximumLevelAtPosition(c));
    return { heights: out.map((c) => c.height), levels };
  }, points);
  console.log(JSON.stringify({ ...report, ...sampled, problems }));
} catch (e) {
  console.error(String(e && e.stack ? e.stack : e));
  status = 1;
} finally {
  await browser.close();
  server.close();
  fs.rmSync(scratch, { recursive: true, force: true });
}
process.exit(status);
