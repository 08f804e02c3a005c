// Headless Chromium as every browser script here launches it (playwright-core driving
// Debian's chromium): WebGL on the CPU through SwiftShader (the machines have no GPU), and
// no background connections (their network is closed). CHROMIUM names another browser.
import fs from 'fs';
import http from 'http';
import path from 'path';
import { chromium } from 'playwright-core';

export function launch() {
  return chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: [
      '--no-sandbox',
      '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader',
      '--ignore-gpu-blocklist',
      '--disable-background-networking',
      '--disable-component-update',
      '--disable-sync',
      '--disable-quic',
      '--no-first-run',
    ],
  });
}

// A local HTTP server for a test page, on a free port of 127.0.0.1: `/` answers `page`,
// `files` maps exact paths to files, `roots` maps path prefixes to directories (nothing above
// them is reachable), and `extra(url, req, res)` may answer first (it returns true when it
// did). Resolves to { server, origin }.
const types = {
  '.js': 'text/javascript', '.mjs': 'text/javascript', '.css': 'text/css', '.json': 'application/json',
  '.wasm': 'application/wasm', '.png': 'image/png', '.jpg': 'image/jpeg',
};
export async function servePage({ page, files = {}, roots = {}, extra = null }) {
  const server = http.createServer((req, res) => {
    const url = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    if (url === '/') {
      res.writeHead(200, { 'Content-Type': 'text/html; charset=utf-8' });
      res.end(page);
      return;
    }
    if (extra && extra(url, req, res)) return;
    let file = files[url] || null;
    for (const [prefix, dir] of Object.entries(roots)) {
      if (url.startsWith(prefix)) {
        const rel = path.normalize(url.slice(prefix.length));
        if (!rel.startsWith('..')) file = path.join(dir, rel);
      }
    }
    fs.readFile(file || '/nonexistent', (err, data) => {
      if (err) {
        res.writeHead(404);
        res.end();
        return;
      }
      res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
      res.end(data);
    });
  });
  await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
  return { server, origin: `http://127.0.0.1:${server.address().port}` };
}
