// The web pages in a real browser: Debian's chromium driven by playwright-core, against a real
// `rally serve` (a child process on a loopback port, a fresh SQLite file, the built-in agents)
// seeded with finished matches. Checks that every page loads without console errors and shows the
// agents' names and numbers, that the replay canvas draws and changes when played, that the
// leaderboard updates without a reload when a match finishes (server-sent events), that a running
// match can be watched live, and that the pages
// fit 1280×800 and a phone's width. With RALLY_MYOCHALLENGE naming the file `rally model import
// myosuite` wrote, the server also plays MyoSuite's robot: its leaderboard behind the page's robot
// switch and a replay drawing its body. Screenshots go to $ARTIFACTS (default target/browser).
//
// Usage (from the repository root, after `cargo build` or `cargo test`):
//   node tests/browser/pages.mjs [path/to/rally]      CHROMIUM=/usr/bin/chromium by default
import { spawn } from 'node:child_process';
import { copyFileSync, mkdirSync, mkdtempSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { createInterface } from 'node:readline';
import { chromium } from 'playwright-core';

const rally = process.argv[2] ?? 'target/debug/rally';
const artifacts = process.env.ARTIFACTS ?? 'target/browser';
const TOKEN = 'browser-test-token';
mkdirSync(artifacts, { recursive: true });
let failures = 0;
const check = (ok, what) => {
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) failures++;
};

// --- the server
const dir = mkdtempSync(join(tmpdir(), 'rally-browser-'));
const myosuite = process.env.RALLY_MYOCHALLENGE;
if (myosuite) {
  mkdirSync(join(dir, 'models'), { recursive: true });
  copyFileSync(myosuite, join(dir, 'models', 'myochallenge.xml'));
}
writeFileSync(join(dir, 'server.toml'), `addr = "127.0.0.1:0"
db = "${process.env.RALLY_TEST_DB || join(dir, 'rally.db')}"
workers = 1
continuous = false
continuous_rallies = 4
continuous_pause_s = 0.0
max_rallies = 1000
qualification_episodes = 6
qualification_min_hit_rate = 0.0
qualification_max_dropped = 1.0
max_body_bytes = 8388608
admin_token = ""
`);
const server = spawn(rally, ['serve', '--config', join(dir, 'server.toml')], {
  // The default robot alone (the test's own data directory), whatever this machine has imported.
  env: { ...process.env, RALLY_DATA_DIR: dir, RALLY_ADMIN_TOKEN: TOKEN, RUST_LOG: 'warn' },
  stdio: ['ignore', 'pipe', 'inherit'],
});
const base = await new Promise((resolve, reject) => {
  const lines = createInterface({ input: server.stdout });
  lines.once('line', l => {
    const m = l.match(/listening on (http:\/\/\S+)/);
    m ? resolve(m[1]) : reject(new Error(`unexpected first line: ${l}`));
  });
  server.once('exit', code => reject(new Error(`rally serve exited with ${code}`)));
});
const api = async (method, path, body) => {
  const r = await fetch(`${base}/api/v1${path}`, {
    method,
    headers: { 'Content-Type': 'application/json', Authorization: `Bearer ${TOKEN}` },
    body: body ? JSON.stringify(body) : undefined,
  });
  return r.json();
};
const finished = async id => {
  for (let i = 0; i < 600; i++) {
    const m = await api('GET', `/matches/${id}`);
    if (m.status === 'done') return m;
    if (m.status === 'failed') throw new Error(`match ${id} failed: ${m.error}`);
    await new Promise(r => setTimeout(r, 100));
  }
  throw new Error(`match ${id} did not finish`);
};

let browser;
try {
  const agents = (await api('GET', '/agents')).agents;
  const names = agents.map(a => a.name);
  check(names.includes('kmac') && names.includes('scripted'), `built-in agents registered (${names.join(', ')})`);
  const kmac = agents.find(a => a.name === 'kmac');
  const first = await api('POST', '/matches', { a: 'kmac', b: 'scripted', rallies: 3, seed: 7 });
  await finished(first.id);
  await finished((await api('POST', '/matches', { a: 'scripted', b: 'scripted-drive', rallies: 2, seed: 8 })).id);

  browser = await chromium.launch({
    executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium',
    args: ['--no-sandbox', '--disable-gpu'],
  });
  const open = async (path, viewport = { width: 1280, height: 800 }) => {
    const page = await browser.newPage({ viewport });
    const errors = [];
    page.on('console', m => { if (m.type() === 'error') errors.push(m.text()); });
    page.on('pageerror', e => errors.push(String(e)));
    await page.goto(`${base}${path}`);
    await page.waitForLoadState('networkidle').catch(() => {});
    return { page, errors };
  };
  const fits = async page => page.evaluate(() => document.documentElement.scrollWidth <= window.innerWidth + 1);

  // --- leaderboard: names and numbers, then live when a match finishes
  {
    const { page, errors } = await open('/');
    await page.waitForSelector('#board tbody tr');
    const board = await page.textContent('#board');
    check(board.includes('kmac') && board.includes('scripted-drive'), 'leaderboard shows the agents');
    check(/\d{3,4}/.test(board) && /\d+%/.test(board), 'leaderboard shows ratings and percentages');
    await page.screenshot({ path: join(artifacts, 'leaderboard.png'), fullPage: true });
    const rows = await page.locator('#matches tbody tr').count();
    await page.evaluate(() => { window.__notReloaded = true; });
    const live = await api('POST', '/matches', { a: 'scripted-soft', b: 'scripted', rallies: 2, seed: 9 });
    await finished(live.id);
    const grew = await page.waitForFunction(
      n => document.querySelectorAll('#matches tbody tr').length > n && window.__notReloaded === true,
      rows, { timeout: 30000 }).then(() => true, () => false);
    check(grew, `the matches table grows without a reload when a match finishes (${rows} rows before)`);
    const status = await page.textContent('#matches tbody tr:first-child');
    check(status.includes('done'), 'and the new match shows as done');
    check(errors.length === 0, `leaderboard: no console errors ${JSON.stringify(errors)}`);
    check(await fits(page), 'leaderboard fits 1280 px');
    await page.close();
  }

  // --- an agent's page
  {
    const { page, errors } = await open(`/agent?id=${kmac.id}`);
    await page.waitForFunction(() => document.querySelector('#title').textContent.includes('kmac'));
    const sub = await page.textContent('#sub');
    check(/hit \d+%/.test(sub) && /rating/.test(sub), `agent page shows its qualification and rating (${sub.slice(0, 80)}…)`);
    check(!(await page.locator('#training-block').isHidden()), 'agent page shows the checkpoint\'s learning curve');
    check((await page.locator('#lengths rect').count()) > 0, 'agent page draws its rally-length histogram');
    await page.screenshot({ path: join(artifacts, 'agent.png'), fullPage: true });
    check(errors.length === 0, `agent page: no console errors ${JSON.stringify(errors)}`);
    await page.close();
  }

  // --- the replay: non-blank canvas that changes when played
  {
    const { page, errors } = await open(`/replay?match=${first.id}&rally=0&camera=behind-a`);
    await page.waitForFunction(() => /frames at/.test(document.querySelector('#msg').textContent));
    const pixels = () => page.evaluate(() => {
      const c = document.querySelector('#view'), d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      let ink = 0, hash = 0;
      for (let i = 0; i < d.length; i += 4) {
        if (d[i + 3] > 0) ink++;
        hash = (hash * 31 + d[i] + 7 * d[i + 1] + 13 * d[i + 2]) >>> 0;
      }
      return { ink, hash };
    });
    const before = await pixels();
    check(before.ink > 10000, `replay canvas draws (${before.ink} painted pixels)`);
    const title = await page.textContent('#title');
    check(title.includes('kmac') && title.includes('scripted'), 'replay names both agents');
    await page.click('#play');
    await page.waitForTimeout(600);
    const after = await pixels();
    check(after.hash !== before.hash, 'the replay canvas changes when played');
    const clock = await page.textContent('#clock');
    check(parseFloat(clock) > 0, `the clock runs (${clock})`);
    await page.keyboard.press('Space');
    await page.keyboard.press('4');
    check((await page.inputValue('#camera')) === 'top', 'keyboard: 4 selects the top camera');
    await page.screenshot({ path: join(artifacts, 'replay.png') });
    check(errors.length === 0, `replay: no console errors ${JSON.stringify(errors)}`);
    await page.close();
  }

  // --- live: a running match's frames reach the viewer as its rallies are played
  {
    const long = await api('POST', '/matches', { a: 'scripted', b: 'scripted-drive', rallies: 150, seed: 10 });
    for (let i = 0; i < 300 && (await api('GET', `/matches/${long.id}`)).status !== 'running'; i++) await new Promise(r => setTimeout(r, 100));
    const { page, errors } = await open(`/replay?match=${long.id}&live=1`);
    const got = await page.waitForFunction(() => /live: rally \d+ of 150/.test(document.querySelector('#msg').textContent), null, { timeout: 30000 })
      .then(() => true, () => false);
    check(got, `the live view receives rallies of a running match (${await page.textContent('#msg')})`);
    const clock0 = await page.textContent('#clock');
    await page.waitForTimeout(400);
    const clock1 = await page.textContent('#clock');
    check(clock1 !== clock0, `the live view plays the frames it receives (clock ${clock0} → ${clock1})`);
    const ink = await page.evaluate(() => {
      const c = document.querySelector('#view'), d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n;
    });
    check(ink > 10000, `the live view draws the robots (${ink} painted pixels)`);
    await page.screenshot({ path: join(artifacts, 'live.png') });
    await api('DELETE', `/matches/${long.id}`);
    check(errors.length === 0, `live view: no console errors ${JSON.stringify(errors)}`);
    await page.close();
  }

  // --- MyoSuite's robot: its own leaderboard behind the switch, its body in the replay
  if (myosuite) {
    const mc = await api('POST', '/matches', { a: 'myochallenge-kmac', b: 'myochallenge-scripted', rallies: 2, seed: 11 });
    check(mc.model === 'myochallenge', `a match of MyoSuite's robot is queued (${mc.model})`);
    await finished(mc.id);
    const { page, errors } = await open('/?model=myochallenge');
    await page.waitForSelector('#board tbody tr');
    const board = await page.textContent('#board');
    check(board.includes('myochallenge-kmac') && !/\bkmac-rally\b/.test(board), 'its leaderboard shows its agents only');
    check(!(await page.locator('#robots').isHidden()) && (await page.inputValue('#robot')) === 'myochallenge',
      'the robot switch shows and names it');
    await page.screenshot({ path: join(artifacts, 'leaderboard-myochallenge.png'), fullPage: true });
    await page.selectOption('#robot', 'default');
    await page.waitForURL(/model=default/);
    await page.waitForSelector('#board tbody tr');
    check((await page.textContent('#board')).includes('kmac-rally'), 'switching back shows the default robot\'s board');
    check(errors.length === 0, `robot switch: no console errors ${JSON.stringify(errors)}`);
    await page.close();
    const replay = await open(`/replay?match=${mc.id}&rally=0`);
    await replay.page.waitForFunction(() => /frames at/.test(document.querySelector('#msg').textContent));
    const ink = await replay.page.evaluate(() => {
      const c = document.querySelector('#view'), d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n;
    });
    check(ink > 10000, `the replay draws MyoSuite's robot (${ink} painted pixels)`);
    check((await replay.page.textContent('#sub')).includes('myochallenge robot'), 'the replay names the robot');
    await replay.page.screenshot({ path: join(artifacts, 'replay-myochallenge.png') });
    check(replay.errors.length === 0, `MyoSuite replay: no console errors ${JSON.stringify(replay.errors)}`);
    await replay.page.close();
  }

  // --- every page at a phone's width
  for (const path of ['/', `/agent?id=${kmac.id}`, `/replay?match=${first.id}&rally=0`]) {
    const { page, errors } = await open(path, { width: 390, height: 844 });
    await page.waitForTimeout(300);
    check(await fits(page), `${path} fits a 390 px phone (no sideways scrolling)`);
    check(errors.length === 0, `${path} at phone width: no console errors ${JSON.stringify(errors)}`);
    if (path === '/') await page.screenshot({ path: join(artifacts, 'leaderboard-phone.png'), fullPage: true });
    await page.close();
  }
} catch (e) {
  check(false, `browser test aborted: ${e.stack ?? e}`);
} finally {
  if (browser) await browser.close();
  server.kill('SIGTERM');
}
console.log(failures === 0 ? 'browser tests: all passed' : `browser tests: ${failures} failed`);
process.exit(failures === 0 ? 0 : 1);
