// Reads a quantized-mesh tileset the way a Cesium globe does, and samples its heights:
// CesiumJS itself (npm `@cesium/engine`) opens the tileset's layer.json through
// CesiumTerrainProvider, served here over HTTP from its directory, and answers
// sampleTerrainMostDetailed for each point. Used by tests/mesh_real.rs, and by
// tests/terrain_cesium.rs with the layer `fmrh serve` serves live (a URL in place of the
// directory).
//
//   node cesium-sample.mjs TILESET_DIR|LAYER_URL POINTS.json
//
// POINTS.json is [[lon, lat], ...] in degrees. Prints one JSON object: for each point, the
// height Cesium gives and the level of the tile it took it from (the deepest available
// there). Exits 2 when the tileset cannot be opened.
import fs from 'fs';
import http from 'http';
import path from 'path';
import * as Cesium from '@cesium/engine';

const [dir, pointsFile] = process.argv.slice(2);
const points = JSON.parse(fs.readFileSync(pointsFile, 'utf8'));

const server = http.createServer((req, res) => {
  const rel = decodeURIComponent(new URL(req.url, 'http://x').pathname);
  const file = path.join(dir, path.normalize(rel).replace(/^(\.\.[/\\])+/, ''));
  fs.readFile(file, (err, data) => {
    if (err) {
      res.writeHead(404);
      res.end();
      return;
    }
    const headers = {
      'Content-Type': file.endsWith('.json') ? 'application/json' : 'application/vnd.quantized-mesh',
    };
    // Tiles stored gzipped (fmrh mesh --gzip) are sent as the specification serves tiles.
    if (data.length >= 2 && data[0] === 0x1f && data[1] === 0x8b) headers['Content-Encoding'] = 'gzip';
    res.writeHead(200, headers);
    res.end(data);
  });
});
// At most 6 requests at once, as a browser keeps to one host over HTTP/1.1: CesiumJS on
// Node.js fetches through undici, which opens as many connections as there are requests
// (hundreds for a sampleTerrainMostDetailed), and `fmrh serve` answers a client past 64
// connections 503. Each response is read whole before its slot is given back.
const realFetch = globalThis.fetch;
let active = 0;
const waiting = [];
globalThis.fetch = async (...args) => {
  while (active >= 6) await new Promise((resolve) => waiting.push(resolve));
  active += 1;
  try {
    const r = await realFetch(...args);
    const body = await r.arrayBuffer();
    return new Response(body, { status: r.status, statusText: r.statusText, headers: r.headers });
  } finally {
    active -= 1;
    const next = waiting.shift();
    if (next) next();
  }
};
let url;
if (/^https?:\/\//.test(dir)) {
  url = dir;
} else {
  await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
  url = `http://127.0.0.1:${server.address().port}/`;
}

let provider;
try {
  provider = await Cesium.CesiumTerrainProvider.fromUrl(url, {
    requestVertexNormals: true,
    requestMetadata: true,
  });
} catch (e) {
  console.error(`cesium: cannot open ${url}: ${e}`);
  process.exit(2);
}
const cartographics = points.map(([lon, lat]) => Cesium.Cartographic.fromDegrees(lon, lat));
// The deepest level with a tile at each point, as sampleTerrainMostDetailed will use (it
// asks the availability, which the root tiles' metadata fills in once loaded).
const sampled = await Cesium.sampleTerrainMostDetailed(provider, cartographics.map((c) => c.clone()));
const levels = cartographics.map((c) => provider.availability.computeMaximumLevelAtPosition(c));
console.log(JSON.stringify({
  hasVertexNormals: provider.hasVertexNormals,
  hasMetadata: provider.hasMetadata,
  heights: sampled.map((c) => c.height ?? null),
  levels,
}));
if (server.listening) server.close();
