// End-to-end test of the web viewer: a real motionlodd (ephemeral loopback port, its own
// data directory) serving web/dist, driven through Debian's Chromium by playwright-core
// (never a downloaded browser), with software WebGL (SwiftShader).
//
// It uploads a real character from ../shared/data through the page's file picker, bakes
// it, moves the level slider and checks every figure the page shows against
// GET /v1/bakes/{id}, reads the pixels of the 3D views (not blank), checks the crowd's
// levels against the daemon's own choice (GET /v1/bakes/{id}/level?px=), shows a refused
// upload's and a refused bake's problem detail, switches the clip of a bake of several
// clips, and saves screenshots in OUTPUT_DIR.
// The page runs under the daemon's Content-Security-Policy: every securitypolicyviolation
// event and every console error fails the test (a probe first shows that a violation is
// caught).
//
// Environment (set by tests/web/CMakeLists.txt): MOTIONLODD, MOTIONLOD_SOURCE_DIR,
// MOTIONLOD_SHARED_DATA, OUTPUT_DIR; CHROMIUM (default /usr/bin/chromium).
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import { createRequire } from 'node:module';
import os from 'node:os';
import path from 'node:path';
import { pathToFileURL } from 'node:url';

const env = (name, fallback) => {
  const value = process.env[name] ?? fallback;
  if (value === undefined) throw new Error(`${name} is not set`);
  return value;
};
const daemonPath = env('MOTIONLODD');
const sourceDir = env('MOTIONLOD_SOURCE_DIR');
const sharedData = env('MOTIONLOD_SHARED_DATA');
const outputDir = env('OUTPUT_DIR');
const chromiumPath = env('CHROMIUM', '/usr/bin/chromium');
const webRoot = path.join(sourceDir, 'web', 'dist');
const characterPath = path.join(sharedData, 'characters', 'CesiumMan.glb');

for (const [what, file, hint] of [
  ['the built viewer', path.join(webRoot, 'index.html'), 'run bash scripts/setup.sh'],
  ['playwright-core', path.join(sourceDir, 'web', 'node_modules', 'playwright-core'), 'run bash scripts/setup.sh'],
  ['Chromium', chromiumPath, 'run bash scripts/setup.sh (it installs Debian\'s chromium)'],
  ['the test character', characterPath, 'the shared test data is missing'],
]) {
  assert.ok(fs.existsSync(file), `${what} is missing (${file}): ${hint}`);
}
const { chromium } = createRequire(path.join(sourceDir, 'web', 'package.json'))('playwright-core');
// The crowd's level choice, as the page runs it.
const { selectLevel } = await import(pathToFileURL(path.join(sourceDir, 'web', 'src', 'level_choice.js')));

const results = { passed: 0, failed: 0 };
async function check(name, body) {
  try {
    await body();
    results.passed += 1;
    console.log(`ok   ${name}`);
  } catch (error) {
    results.failed += 1;
    console.log(`FAIL ${name}\n     ${String(error.stack || error).split('\n').join('\n     ')}`);
  }
}

// ---- the daemon ------------------------------------------------------------------------

function startDaemon(dataDir) {
  const child = spawn(
    daemonPath,
    ['--port', '0', '--data-dir', dataDir, '--web-root', webRoot, '--threads', '1', '--bake-threads', '2',
      '--access-log', 'false'],
    { stdio: ['ignore', 'pipe', 'pipe'] },
  );
  const log = fs.createWriteStream(path.join(outputDir, 'daemon.log'));
  child.stderr.pipe(log);
  return new Promise((resolve, reject) => {
    let out = '';
    const timer = setTimeout(() => reject(new Error(`motionlodd did not start within 30 s: ${out}`)), 30000);
    child.stdout.on('data', (chunk) => {
      out += chunk;
      const match = /listening on (http:\/\/[^\s]+)/.exec(out);
      if (match) {
        clearTimeout(timer);
        resolve({ child, base: match[1] });
      }
    });
    child.on('exit', (code) => reject(new Error(`motionlodd exited with ${code}: ${out}`)));
  });
}

async function api(base, route, headers = {}) {
  const response = await fetch(base + route, { headers: { Accept: 'application/json', ...headers } });
  assert.equal(response.status, 200, `${route}: ${response.status} ${await response.clone().text()}`);
  return response.json();
}

async function bakeOverApi(base, request) {
  const submitted = await fetch(`${base}/v1/bakes`, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify(request),
  });
  assert.equal(submitted.status, 202, await submitted.clone().text());
  let status = await submitted.json();
  while (status.state !== 'succeeded' && status.state !== 'failed') {
    status = await api(base, `/v1/jobs/${status.id}?wait=20&after=${status.version}`);
  }
  assert.equal(status.state, 'succeeded', JSON.stringify(status.error));
  return api(base, `/v1/bakes/${status.id}`);
}

// The level table's ranges partition (0, inf), and at heights across them (every bound, the
// next double either side, and between) the page's choice (web/src/level_choice.js), the
// daemon's `level?px=` and the range holding the height name the same level.
async function expectOneLevelChoice(base, bake) {
  const chosen = bake.levels.filter((level) => level.chosen).sort((a, b) => a.px_min - b.px_min);
  assert.ok(chosen.length > 0);
  assert.equal(chosen[0].px_min, 0);
  for (let k = 0; k < chosen.length; ++k) {
    const { px_min: low, px_max: high } = chosen[k];
    if (k + 1 < chosen.length) {
      assert.ok(high !== null && low < high, `level ${chosen[k].index}: empty range (${low}, ${high}]`);
      assert.equal(chosen[k + 1].px_min, high, `level ${chosen[k + 1].index}: a gap or an overlap`);
    } else {
      assert.equal(high, null, 'the finest chosen level serves every larger height');
    }
  }
  for (const level of bake.levels.filter((l) => !l.chosen)) {
    assert.equal(level.px_min, null);
    assert.equal(level.px_max, null);
  }
  const heights = [0.25, 3, 40, 700, 1e6];
  for (const { px_max: bound } of chosen) {
    if (bound !== null) heights.push(bound, bound * (1 - 1e-15), bound * (1 + 1e-15), bound * 0.8);
  }
  for (const px of heights.filter((h) => h > 0 && h <= 1e6)) {
    const daemon = await api(base, `/v1/bakes/${bake.id}/level?px=${px}`);
    const page = selectLevel(bake.levels, px);
    const level = bake.levels[page];
    assert.equal(page, daemon.index, `${px} px: the page picks ${page}, the daemon ${daemon.index}`);
    assert.ok(level.chosen && px > level.px_min && (level.px_max === null || px <= level.px_max),
      `${px} px outside the range of level ${page}`);
  }
}

// ---- page helpers ----------------------------------------------------------------------

// Share of a canvas's pixels that differ clearly from its background colour.
function drawnShare(page, selector) {
  return page.evaluate((sel) => {
    const canvas = document.querySelector(sel);
    const copy = document.createElement('canvas');
    copy.width = canvas.width;
    copy.height = canvas.height;
    const context = copy.getContext('2d');
    context.drawImage(canvas, 0, 0);
    const { data } = context.getImageData(0, 0, copy.width, copy.height);
    const background = [0xe9, 0xec, 0xf2];
    let drawn = 0;
    for (let i = 0; i < data.length; i += 4) {
      const d = Math.abs(data[i] - background[0]) + Math.abs(data[i + 1] - background[1]) + Math.abs(data[i + 2] - background[2]);
      if (d > 24) drawn += 1;
    }
    return drawn / (copy.width * copy.height);
  }, selector);
}

async function figures(page) {
  return page.$$eval('#level-figures td[data-field]', (cells) =>
    Object.fromEntries(cells.map((cell) => [cell.dataset.field, { value: cell.dataset.value, text: cell.textContent }])),
  );
}

async function moveSlider(page, index) {
  await page.$eval('#level-slider', (slider, value) => {
    slider.value = String(value);
    slider.dispatchEvent(new Event('input', { bubbles: true }));
  }, index);
  await page.waitForFunction((value) => window.motionlodViewer.state.levelIndex === value, index);
}

// ---- the test ----------------------------------------------------------------------------

fs.mkdirSync(outputDir, { recursive: true });
const work = fs.mkdtempSync(path.join(os.tmpdir(), 'motionlod-web-'));
const { child: daemon, base } = await startDaemon(path.join(work, 'data'));
// No daemon outlives the test, however it ends.
process.on('exit', () => daemon.kill('SIGKILL'));
let browser = null;
try {
  // launch() gives the browser a fresh temporary profile.
  browser = await chromium.launch({
    executablePath: chromiumPath,
    headless: true,
    args: ['--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader', '--ignore-gpu-blocklist',
      '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run',
      '--disable-quic'],
  });
  // Console errors, page errors and every Content-Security-Policy violation of a page,
  // the last reported from the page through a binding (set up by the browser, not
  // subject to the policy).
  const watch = async (target) => {
    const seen = { consoleErrors: [], cspViolations: [] };
    target.on('console', (message) => {
      if (message.type() === 'error') seen.consoleErrors.push(message.text());
    });
    target.on('pageerror', (error) => seen.consoleErrors.push(String(error)));
    await target.exposeFunction('motionlodReportCspViolation', (violation) => seen.cspViolations.push(violation));
    await target.addInitScript(() => {
      document.addEventListener('securitypolicyviolation', (event) => {
        window.motionlodReportCspViolation({
          directive: event.effectiveDirective, blocked: event.blockedURI, source: `${event.sourceFile}:${event.lineNumber}`,
        });
      });
    });
    return seen;
  };
  const page = await browser.newPage({ viewport: { width: 1360, height: 1000 }, deviceScaleFactor: 1 });
  const { consoleErrors, cspViolations } = await watch(page);
  // Every request of the page answered 404 (the favicon included): none is expected.
  const notFound = [];
  page.on('response', (response) => {
    if (response.status() === 404) notFound.push(response.url());
  });
  // The headers of the first response for the page and each of its files.
  const viewerResponses = new Map();
  page.on('response', (response) => {
    const route = new URL(response.url()).pathname;
    if ((route === '/' || route.startsWith('/assets/')) && !viewerResponses.has(route)) {
      viewerResponses.set(route, response.headers());
    }
  });
  const until = async (what, predicate) => {
    for (let waited = 0; !predicate(); waited += 50) {
      assert.ok(waited < 30000, `no ${what} within 30 s`);
      await new Promise((resolve) => setTimeout(resolve, 50));
    }
  };

  await check('the daemon serves the viewer at / as HTML', async () => {
    const response = await page.goto(`${base}/`);
    assert.equal(response.status(), 200);
    assert.match(response.headers()['content-type'], /^text\/html/);
    await page.waitForSelector('#drop-zone');
    const icon = await page.$eval('link[rel="icon"]', (link) => link.href);
    const served = await fetch(icon);
    assert.equal(served.status, 200, `the favicon ${icon}`);
    assert.match(served.headers.get('content-type'), /^image\/svg\+xml/);
  });

  await check('the viewer and its files carry the security headers', async () => {
    const served = [...viewerResponses.keys()];
    for (const kind of [/^\/$/, /^\/assets\/.+\.js$/, /^\/assets\/.+\.css$/]) {
      assert.ok(served.some((route) => kind.test(route)), `${kind} not among ${served}`);
    }
    for (const [route, headers] of viewerResponses) {
      assert.equal(headers['x-content-type-options'], 'nosniff', route);
      assert.equal(headers['referrer-policy'], 'no-referrer', route);
      assert.equal(headers['x-frame-options'], 'DENY', route);
      assert.match(headers['content-security-policy'], /^default-src 'self'; script-src 'self'; style-src 'self';/, route);
      assert.match(headers['content-security-policy'], /frame-ancestors 'none'/, route);
    }
  });

  await check('a policy violation is caught (an inline style attribute is refused)', async () => {
    // On a page of its own, so that its expected violation cannot mix with the viewer's.
    const probe = await browser.newPage();
    try {
      const seen = await watch(probe);
      await probe.goto(`${base}/`);
      const applied = await probe.evaluate(() => {
        const element = document.createElement('div');
        element.setAttribute('style', 'color: rgb(1, 2, 3)');
        document.body.append(element);
        return getComputedStyle(element).color === 'rgb(1, 2, 3)';
      });
      assert.equal(applied, false, 'the inline style was applied: no Content-Security-Policy in force');
      await until('securitypolicyviolation event', () => seen.cspViolations.length > 0);
      const policyErrors = () => seen.consoleErrors.filter((text) => !/Failed to load resource/.test(text));
      await until('console error', () => policyErrors().length > 0);
      assert.ok(seen.cspViolations.every((v) => v.directive === 'style-src-attr'), JSON.stringify(seen.cspViolations));
      assert.ok(policyErrors().every((text) => /Content Security Policy/.test(text)), policyErrors().join('\n'));
    } finally {
      await probe.close();
    }
  });

  await check('WebGL is available (software rendering)', async () => {
    const renderer = await page.evaluate(() => {
      const gl = document.createElement('canvas').getContext('webgl2');
      return gl ? gl.getParameter(gl.RENDERER) : null;
    });
    assert.ok(renderer, 'no WebGL 2 context');
    console.log(`     WebGL renderer: ${renderer}`);
  });

  await check('a refused upload (dropped on the page) shows the problem detail', async () => {
    const bytes = Buffer.from('this is not a glTF file');
    const direct = await fetch(`${base}/v1/characters?filename=broken.glb`, {
      method: 'POST', headers: { 'Content-Type': 'application/octet-stream' }, body: bytes,
    });
    const problem = await direct.json();
    assert.ok(direct.status >= 400 && direct.status < 500, `status ${direct.status}`);
    await page.evaluate((text) => {
      const transfer = new DataTransfer();
      transfer.items.add(new File([text], 'broken.glb', { type: 'model/gltf-binary' }));
      const drop = new DragEvent('drop', { dataTransfer: transfer, bubbles: true, cancelable: true });
      document.getElementById('drop-zone').dispatchEvent(drop);
    }, bytes.toString());
    await page.waitForSelector('#error:not([hidden])');
    const shown = await page.textContent('#error');
    assert.ok(shown.includes(problem.detail), `"${shown}" lacks the daemon's detail "${problem.detail}"`);
    assert.ok(shown.includes(`HTTP ${direct.status}`), shown);
    await page.screenshot({ path: path.join(outputDir, 'upload-refused.png') });
  });

  let bake = null;
  await check('upload, bake with a progress bar, and the level table', async () => {
    await page.setInputFiles('#file-input', characterPath);
    await page.waitForFunction(() => document.querySelectorAll('#motion option').length > 0);
    assert.equal(await page.isHidden('#error'), true, await page.textContent('#error'));
    // A bake the daemon refuses: its problem detail is shown.
    const character = await page.evaluate(() => window.motionlodViewer.state.character.id);
    const refused = await fetch(`${base}/v1/bakes`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify({ character, motion: await page.inputValue('#motion'), variant: 'vpno+pd', levels: [70000] }),
    });
    assert.equal(refused.status, 400);
    const refusal = await refused.json();
    await page.fill('#levels', '70000');
    await page.click('#bake-button');
    await page.waitForSelector('#error:not([hidden])');
    assert.ok((await page.textContent('#error')).includes(refusal.detail), await page.textContent('#error'));
    await page.fill('#levels', '');
    await page.click('#bake-button');
    await page.waitForFunction(() => document.getElementById('progress-text').textContent.length > 0);
    await page.waitForFunction(() => window.motionlodViewer.state.bake !== null, null, { timeout: 600000 });
    assert.equal(await page.$eval('#progress', (p) => p.value), 1);
    const id = await page.evaluate(() => window.motionlodViewer.state.bake.id);
    bake = await api(base, `/v1/bakes/${id}`);
    assert.equal(bake.state, 'succeeded');
    assert.ok(bake.levels.length >= 3, `${bake.levels.length} levels`);
  });
  assert.ok(bake, 'no bake to look at');

  const exportCheck = await fetch(`${base}/v1/bakes/${bake.id}/levels/${bake.levels[0].hash}.glb`);
  const levelsExported = exportCheck.status === 200;
  console.log(`     level export route: ${levelsExported ? 'present' : `absent (${exportCheck.status})`}`);

  await check('the slider shows each level\'s figures as GET /v1/bakes/{id} gives them', async () => {
    for (let index = bake.levels.length - 1; index >= 0; --index) {
      await moveSlider(page, index);
      const level = bake.levels[index];
      const shown = await figures(page);
      for (const field of ['joints', 'vertices', 'triangles', 'frame_stride', 'stream_bytes_per_second', 'cost',
        'max_vertex_error_pct', 'mean_vertex_error_pct', 'mean_normal_error_deg', 'mean_E', 'bytes']) {
        assert.equal(Number(shown[field].value), level[field], `level ${index} ${field}`);
      }
      assert.equal(shown.influences_per_vertex.value === '' ? null : Number(shown.influences_per_vertex.value),
        level.influences_per_vertex, `level ${index} influences_per_vertex`);
      assert.match(shown.influences_per_vertex.text,
        level.influences_per_vertex === null ? /^the mesh's/ : new RegExp(`^at most ${level.influences_per_vertex},`));
      const limit = level.max_px_for_1px_error;
      assert.equal(shown.max_px_for_1px_error.value === '' ? null : Number(shown.max_px_for_1px_error.value), limit);
      assert.match(shown.max_vertex_error_pct.text, new RegExp(`^${level.max_vertex_error_pct.toFixed(3)} `));
      // (px_min, px_max] in tenths; a sliver that would print empty says what it is.
      if (level.chosen && level.px_max !== null && level.px_min.toFixed(1) === level.px_max.toFixed(1)) {
        assert.ok(shown.px_range.text.startsWith(`only about ${level.px_max.toFixed(1)} px`), shown.px_range.text);
      } else if (level.chosen) {
        const high = level.px_max === null ? '∞' : level.px_max.toFixed(1);
        assert.equal(shown.px_range.text, `(${level.px_min.toFixed(1)}, ${high}] px`);
      } else {
        assert.match(shown.px_range.text, /^never/);
      }
      assert.ok((await page.textContent('#level-label')).includes(`${level.joints} of ${bake.levels[0].joints}`));
    }
    await moveSlider(page, bake.levels.length - 1);
  });

  await check('both views play and are not blank', async () => {
    const start = await page.evaluate(() => window.motionlodViewer.compareFrames);
    await page.waitForFunction((n) => window.motionlodViewer.compareFrames > n + 5, start, { timeout: 120000 });
    await page.waitForFunction(() => window.motionlodViewer.viewBones.level > 0, null, { timeout: 120000 });
    for (const selector of ['#view-original', '#view-level']) {
      const share = await drawnShare(page, selector);
      console.log(`     ${selector}: ${(share * 100).toFixed(1)}% of the pixels drawn`);
      assert.ok(share > 0.01, `${selector} is blank (${share})`);
    }
    const bones = await page.evaluate(() => window.motionlodViewer.viewBones);
    if (levelsExported) {
      const coarsest = bake.levels[bake.levels.length - 1];
      assert.equal(bones.level, coarsest.joints, 'the level view has the level\'s skeleton');
      assert.equal(bones.original, bake.levels[0].joints, 'the original has every joint');
    }
    await page.locator('#compare').screenshot({ path: path.join(outputDir, 'compare.png') });
  });

  await check('the error curve and the joint priority table', async () => {
    const report = await api(base, `/v1/bakes/${bake.id}/report`);
    const rows = await page.$$eval('#ranking tbody tr', (trs) => trs.map((tr) => tr.dataset.joint));
    assert.deepEqual(rows, report.ranking.map((r) => r.joint));
    const paths = await page.$$eval('#error-curve path', (ps) => ps.map((p) => p.dataset.series));
    assert.deepEqual(paths.slice(0, 2), [bake.variant, `${bake.variant} unoptimised`]);
    const points = await page.$$eval('#error-curve circle', (cs) => cs.length);
    assert.ok(points >= 2 * bake.levels.length, `${points} points`);
    // The coarsest level removes joints: their rows are struck through.
    const removed = await page.$$eval('#ranking tr.removed', (trs) => trs.map((tr) => tr.dataset.joint).sort());
    assert.deepEqual(removed, [...report.levels[report.levels.length - 1].removed].sort());
    await page.locator('#curves').screenshot({ path: path.join(outputDir, 'curves.png') });
  });

  await check('the page\'s level choice is the daemon\'s across the level table', async () => {
    await expectOneLevelChoice(base, bake);
  });

  await check('the crowd uses the level the daemon selects for each height', async () => {
    await page.waitForFunction(() => window.motionlodViewer.crowdMembers.length > 0, null, { timeout: 120000 });
    const members = await page.evaluate(() => window.motionlodViewer.crowdMembers);
    assert.equal(members.length, 300);
    const used = new Set(members.map((m) => m.level));
    assert.ok(used.size >= 2, `the crowd uses ${used.size} level(s)`);
    const sample = [...members].sort((a, b) => a.px - b.px).filter((_, k, all) => k % Math.ceil(all.length / 15) === 0);
    for (const member of sample) {
      const choice = await api(base, `/v1/bakes/${bake.id}/level?px=${member.px}`);
      assert.equal(member.level, choice.index, `${member.px.toFixed(2)} px`);
      assert.equal(member.joints, choice.joints);
    }
    const legend = await page.$$eval('#crowd-legend span', (spans) => spans.reduce((sum, s) => sum + Number(s.dataset.count), 0));
    assert.equal(legend, 300);
    await page.evaluate(() => new Promise((resolve) => requestAnimationFrame(() => requestAnimationFrame(resolve))));
    const share = await drawnShare(page, '#view-crowd');
    console.log(`     #view-crowd: ${(share * 100).toFixed(1)}% of the pixels drawn`);
    assert.ok(share > 0.01, `the crowd is blank (${share})`);
    await page.locator('#crowd').screenshot({ path: path.join(outputDir, 'crowd.png') });
  });

  await check('a bake without the full level shows its finest level in place of the original', async () => {
    // Two levels, neither with every joint, opened from the page's list (no uploaded file
    // to stand in for the original).
    const all = bake.levels[0].joints;
    const partial = await bakeOverApi(base, {
      character: bake.character, motion: bake.motion, variant: bake.variant, levels: [all - 3, 5],
    });
    await expectOneLevelChoice(base, partial);
    await page.goto(`${base}/`);
    await page.waitForFunction((wanted) => [...document.querySelectorAll('#bake-list option')].some((o) => o.value === wanted), partial.id);
    await page.selectOption('#bake-list', partial.id);
    await page.waitForFunction((wanted) => window.motionlodViewer.state.bake?.id === wanted, partial.id, { timeout: 120000 });
    await page.waitForFunction(() => window.motionlodViewer.viewBones.level > 0, null, { timeout: 120000 });
    const start = await page.evaluate(() => window.motionlodViewer.compareFrames);
    await page.waitForFunction((n) => window.motionlodViewer.compareFrames > n + 5, start, { timeout: 120000 });
    for (const selector of ['#view-original', '#view-level']) {
      const share = await drawnShare(page, selector);
      console.log(`     ${selector}: ${(share * 100).toFixed(1)}% of the pixels drawn`);
      assert.ok(share > 0.01, `${selector} is blank (${share})`);
    }
    const finest = partial.levels[0].joints;
    assert.equal(await page.textContent('#caption-original'), `finest level baked: ${finest} of ${all} joints`);
    assert.match(await page.textContent('#compare-note'), new RegExp(`no level with all ${all} joints: .*finest level, ${finest} joints`));
    if (levelsExported) assert.equal((await page.evaluate(() => window.motionlodViewer.viewBones)).original, finest);
    await page.locator('#compare').screenshot({ path: path.join(outputDir, 'compare-partial.png') });
  });

  await check('another variant\'s bake joins the curve; a bake opens from the list', async () => {
    const vp = await bakeOverApi(base, { character: bake.character, motion: bake.motion, variant: 'vp' });
    // Open the vp bake, then the first one again, from the page's list of bakes.
    for (const id of [vp.id, bake.id]) {
      await page.goto(`${base}/`);  // no #bake= in the address: nothing opens by itself
      await page.waitForFunction((wanted) => [...document.querySelectorAll('#bake-list option')].some((o) => o.value === wanted), id);
      await page.selectOption('#bake-list', id);
      await page.waitForFunction((wanted) => window.motionlodViewer.state.bake?.id === wanted, id, { timeout: 120000 });
    }
    await page.waitForFunction(() => document.querySelector('#error-curve path[data-series="vp"]') !== null);
    const circles = await page.$$eval('#error-curve circle', (cs) => cs.length);
    assert.equal(circles, 2 * bake.levels.length + vp.levels.length);
    await page.waitForFunction(() => window.motionlodViewer.crowdMembers.length > 0, null, { timeout: 120000 });
  });

  await check('a bake of several clips: the clip selector switches what the views and the crowd play', async () => {
    const fox = path.join(sharedData, 'characters', 'Fox.glb');
    const uploaded = await fetch(`${base}/v1/characters?filename=Fox.glb`, {
      method: 'POST', headers: { 'Content-Type': 'application/octet-stream' }, body: fs.readFileSync(fox),
    });
    assert.ok(uploaded.status === 201 || uploaded.status === 200, `upload: ${uploaded.status}`);
    const character = await uploaded.json();
    const clips = ['Walk', 'Run'];
    const multi = await bakeOverApi(base, { character: character.id, clips, levels: [character.joints, 12, 6] });
    assert.deepEqual(multi.clips.map((clip) => clip.animation), clips);
    // One clip's frames of the level for a height, as the daemon serves them.
    for (const clip of multi.clips) {
      const choice = await api(base, `/v1/bakes/${multi.id}/level?px=50&clip=${clip.animation}`);
      assert.equal(choice.clip, clip.animation);
      const level = await fetch(base + choice.url);
      assert.equal(level.status, 200);
    }
    await page.goto(`${base}/`);
    await page.waitForFunction((wanted) => [...document.querySelectorAll('#bake-list option')].some((o) => o.value === wanted), multi.id);
    await page.selectOption('#bake-list', multi.id);
    await page.waitForFunction((wanted) => window.motionlodViewer.state.bake?.id === wanted, multi.id, { timeout: 120000 });
    // A bake of several clips shows the clip selector once its clips are listed.
    await page.waitForSelector('#clip', { state: 'visible', timeout: 120000 });
    assert.deepEqual(await page.$$eval('#clip option', (options) => options.map((o) => o.value)), clips);
    const playing = (clip) => page.waitForFunction((name) => {
      const views = window.motionlodViewer.playing;
      return views?.original === name && views?.level === name;
    }, clip, { timeout: 120000 });
    await playing('Walk');
    await page.waitForFunction(() => window.motionlodViewer.crowdMembers.length > 0, null, { timeout: 120000 });
    let members = await page.evaluate(() => window.motionlodViewer.crowdMembers);
    assert.deepEqual([...new Set(members.map((m) => m.clip))].sort(), [...clips].sort(), 'the crowd plays every clip');
    assert.equal(members[0].clip, 'Walk');

    await page.selectOption('#clip', 'Run');
    await playing('Run');
    await page.waitForFunction(() => window.motionlodViewer.crowdMembers[0]?.clip === 'Run', null, { timeout: 120000 });
    members = await page.evaluate(() => window.motionlodViewer.crowdMembers);
    assert.deepEqual([...new Set(members.map((m) => m.clip))].sort(), [...clips].sort());
    const start = await page.evaluate(() => window.motionlodViewer.compareFrames);
    await page.waitForFunction((n) => window.motionlodViewer.compareFrames > n + 5, start, { timeout: 120000 });
    for (const selector of ['#view-original', '#view-level', '#view-crowd']) {
      const share = await drawnShare(page, selector);
      assert.ok(share > 0.005, `${selector} is blank (${share})`);
    }
    assert.equal(await page.isHidden('#error'), true, await page.textContent('#error'));
    await page.locator('#compare').screenshot({ path: path.join(outputDir, 'compare-clips.png') });
  });

  await check('a full page screenshot, no script errors and no policy violations', async () => {
    // Reported, not asserted (no timing assertions): the page's frame rate with both
    // views and the crowd drawing in software.
    const before = await page.evaluate(() => window.motionlodViewer.compareFrames);
    await page.waitForTimeout(5000);
    const after = await page.evaluate(() => window.motionlodViewer.compareFrames);
    console.log(`     ${((after - before) / 5).toFixed(1)} frames per second (two views and a 300-character crowd)`);
    await page.screenshot({ path: path.join(outputDir, 'page.png'), fullPage: true });
    assert.deepEqual(cspViolations, []);
    // A refused upload or bake logs "Failed to load resource" with its 400; a 404 never.
    const unexpected = consoleErrors.filter((text) => !/Failed to load resource/.test(text) || /404/.test(text));
    assert.deepEqual(unexpected, []);
    assert.deepEqual(notFound, []);
  });
} finally {
  await browser?.close();
  daemon.kill('SIGTERM');
  await new Promise((resolve) => daemon.once('exit', resolve));
  if (results.failed === 0) fs.rmSync(work, { recursive: true, force: true });
}

console.log(`screenshots in ${outputDir}`);
console.log(`${results.passed} passed, ${results.failed} failed`);
process.exit(results.failed === 0 ? 0 : 1);
