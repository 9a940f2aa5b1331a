// Drives the anymo web page in headless Chromium, as a user would, and checks that what it shows
// is real: generated motion plays (the frame counter advances and the canvas's pixels change)
// with its quality report beside it, the controls and keys work, an API error appears in place, the library searches and previews,
// "find similar" and the clip details work, and a transfer plays side by side.
//
// node page.mjs --base URL --out DIR --skeleton FILE.bvh --broken FILE.bvh --query WORDS
// Screenshots go to DIR. Exits non-zero, saying which step failed, on any failure.

import { chromium } from 'playwright-core';
import { inflateSync } from 'node:zlib';
import { mkdirSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';

const args = Object.fromEntries(
  process.argv.slice(2).reduce((pairs, a, i, all) => (a.startsWith('--') ? [...pairs, [a.slice(2), all[i + 1]]] : pairs), []),
);
for (const need of ['base', 'out', 'skeleton', 'broken', 'query']) {
  if (!args[need]) throw new Error(`--${need} is required`);
}
mkdirSync(args.out, { recursive: true });

/** The pixels of an 8-bit RGB or RGBA PNG, as Chromium writes its screenshots. */
function decodePng(buf) {
  let at = 8;
  let header;
  const data = [];
  while (at < buf.length) {
    const length = buf.readUInt32BE(at);
    const type = buf.toString('ascii', at + 4, at + 8);
    const chunk = buf.subarray(at + 8, at + 8 + length);
    if (type === 'IHDR') {
      header = { width: chunk.readUInt32BE(0), height: chunk.readUInt32BE(4), depth: chunk[8], color: chunk[9], interlace: chunk[12] };
    } else if (type === 'IDAT') {
      data.push(chunk);
    } else if (type === 'IEND') {
      break;
    }
    at += 12 + length;
  }
  const { width, height, depth, color, interlace } = header;
  if (depth !== 8 || ![2, 6].includes(color) || interlace) throw new Error(`unexpected PNG format ${depth}/${color}/${interlace}`);
  const bpp = color === 6 ? 4 : 3;
  const raw = inflateSync(Buffer.concat(data));
  const stride = width * bpp;
  const px = Buffer.alloc(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const a = x >= bpp ? px[y * stride + x - bpp] : 0;
      const b = y > 0 ? px[(y - 1) * stride + x] : 0;
      const c = x >= bpp && y > 0 ? px[(y - 1) * stride + x - bpp] : 0;
      let v = line[x];
      if (filter === 1) v += a;
      else if (filter === 2) v += b;
      else if (filter === 3) v += (a + b) >> 1;
      else if (filter === 4) {
        const p = a + b - c;
        const pa = Math.abs(p - a);
        const pb = Math.abs(p - b);
        const pc = Math.abs(p - c);
        v += pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      }
      px[y * stride + x] = v & 255;
    }
  }
  return { width, height, bpp, px };
}

/** The share of pixels where `a` and `b` differ by more than a little in any channel. */
function changed(a, b) {
  if (a.width !== b.width || a.height !== b.height) return 1;
  let n = 0;
  for (let i = 0; i < a.width * a.height; i++) {
    for (let k = 0; k < 3; k++) {
      if (Math.abs(a.px[i * a.bpp + k] - b.px[i * b.bpp + k]) > 8) {
        n++;
        break;
      }
    }
  }
  return n / (a.width * a.height);
}

/** The share of pixels that are neither the stage's background nor the grid's greys: the skeleton. */
function drawn(img) {
  let n = 0;
  for (let i = 0; i < img.width * img.height; i++) {
    const [r, g, b] = [img.px[i * img.bpp], img.px[i * img.bpp + 1], img.px[i * img.bpp + 2]];
    if (Math.max(r, g, b) - Math.min(r, g, b) > 40) n++;
  }
  return n / (img.width * img.height);
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
let step = 'starting Chromium';
const errors = [];
const report = {};

function check(ok, message) {
  if (!ok) throw new Error(message);
}

/**
 * Checks that a player plays: its frame counter shows at least three frames within a second, its
 * canvas shows a skeleton, and two screenshots differ. A short loop can come round to the same
 * frame, so a pair of screenshots is taken up to four times.
 */
async function plays(viewer, name) {
  const canvas = viewer.locator('canvas');
  await canvas.waitFor();
  const frames = await viewer.locator('output.frame').evaluate(async (out) => {
    const seen = new Set();
    for (let i = 0; i < 20; i++) {
      seen.add(Number(out.dataset.frame));
      await new Promise((r) => setTimeout(r, 50));
    }
    return [...seen];
  });
  check(frames.length >= 3, `${name}: the frame counter showed only frames ${frames} in a second`);
  let moved = 0;
  let figure = 0;
  for (let attempt = 0; attempt < 4 && moved <= 0.0005; attempt++) {
    const a = decodePng(await canvas.screenshot({ path: join(args.out, `${name}-1.png`) }));
    await sleep(300);
    const b = decodePng(await canvas.screenshot({ path: join(args.out, `${name}-2.png`) }));
    moved = changed(a, b);
    figure = drawn(a);
  }
  report[name] = { frames: frames.length, changed: Number(moved.toFixed(4)), drawn: Number(figure.toFixed(4)) };
  check(figure > 0.002, `${name}: the canvas shows no skeleton (${figure} of its pixels are coloured)`);
  check(moved > 0.0005, `${name}: the canvas did not change between two screenshots (${moved})`);
}

const browser = await chromium.launch({
  executablePath: process.env.ANYMO_CHROMIUM || '/usr/bin/chromium',
  args: [
    '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-quic',
    '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync',
  ],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  page.setDefaultTimeout(120_000);
  page.on('pageerror', (e) => errors.push(`page error: ${e.message}`));

  step = 'loading the page';
  await page.goto(`${args.base}/`);
  await page.waitForSelector('body[data-ready="true"]');
  check((await page.locator('#server-status').textContent()).includes('clips'), 'the page does not say what the server holds');

  step = 'showing an API error in place (a malformed skeleton)';
  await page.fill('#prompt', 'a dog walks forward');
  await page.setInputFiles('#generate-skeleton-file', args.broken);
  await page.click('#generate-button');
  const error = page.locator('#generate-form .error');
  await error.waitFor({ state: 'visible' });
  const said = await error.textContent();
  report.error = said;
  check(/line \d+/.test(said), `the error does not name the line: ${said}`);

  step = 'generating on an uploaded skeleton';
  await page.setInputFiles('#generate-skeleton-file', args.skeleton);
  await page.fill('#seconds', '3');
  await page.fill('#samples', '2');
  await page.fill('#seed', '7');
  await page.click('#generate-button');
  await page.waitForFunction(() => document.querySelectorAll('#generate-results .viewer canvas').length === 2);
  check(await error.isHidden(), 'the old error is still shown after a success');
  report.generateStatus = await page.locator('#generate-form .status').textContent();
  const first = page.locator('#generate-results .viewer').first();
  await plays(first, 'generate-sample');
  // Each sample shows its quality report; the test asserts it says the motion is plausible.
  check(await first.locator('dl.quality dd').count() >= 4, 'the sample shows no quality report');
  report.generateQuality = JSON.parse(await first.getAttribute('data-quality'));
  await page.screenshot({ path: join(args.out, 'generate.png') });
  const download = await first.locator('a.download').getAttribute('href');
  const bvh = await (await page.request.get(`${args.base}${download}`)).text();
  const frames = Number(/Frames:\s*(\d+)/.exec(bvh)?.[1]);
  const frameTime = Number(/Frame Time:\s*([0-9.eE+-]+)/.exec(bvh)?.[1]);
  check(bvh.startsWith('HIERARCHY') && Math.abs(frames * frameTime - 3) <= 1.01 * frameTime,
    `the download is not the 3 s sample: ${frames} frames of ${frameTime} s`);

  step = 'pausing, stepping by keyboard, changing speed';
  await first.locator('button.play').click();
  const paused = Number(await first.locator('output.frame').getAttribute('data-frame'));
  await sleep(500);
  check(Number(await first.locator('output.frame').getAttribute('data-frame')) === paused, 'the player did not pause');
  await first.locator('canvas').focus();
  await page.keyboard.press('ArrowRight');
  check(Number(await first.locator('output.frame').getAttribute('data-frame')) === Math.min(paused + 1, frames - 1),
    'the right arrow did not step one frame');
  await page.keyboard.press('Home');
  check(Number(await first.locator('output.frame').getAttribute('data-frame')) === 0, 'Home did not go to the first frame');
  await first.locator('input.scrub').fill('45');
  check(Number(await first.locator('output.frame').getAttribute('data-frame')) === 45, 'scrubbing did not move to frame 45');
  await first.locator('select').selectOption('2');
  await first.locator('canvas').focus();
  await page.keyboard.press(' ');
  await plays(first, 'generate-sample-fast');

  step = 'opening the library by keyboard';
  await page.focus('nav a[data-view="library"]');
  await page.keyboard.press('Enter');
  await page.waitForSelector('#view-library:not([hidden])');
  await page.waitForSelector('#results .hit');

  step = 'searching the library';
  await page.fill('#search-q', args.query);
  await page.keyboard.press('Enter');
  await page.waitForFunction((q) => document.getElementById('results-title').textContent.includes(q), args.query);
  await page.waitForSelector('#results .hit');
  const hits = page.locator('#results .hit');
  report.hits = await hits.count();
  report.firstHit = await hits.first().locator('h4').textContent();
  check(report.hits > 0, 'the search found nothing');

  step = 'filtering the search';
  const subject = await page.locator('#filter-subject option').evaluateAll(
    (options) => options.map((o) => o.value).find((v) => v && !v.includes('horse')));
  await page.selectOption('#filter-subject', subject);
  await page.waitForFunction((s) => {
    const metas = [...document.querySelectorAll('#results .hit .meta')].map((m) => m.textContent);
    return metas.length > 0 && metas.every((m) => m.startsWith(`${s} ·`));
  }, subject);
  report.filtered = { subject, hits: await hits.count() };
  await page.selectOption('#filter-subject', '');
  await page.waitForFunction(() => document.querySelector('#results .hit .meta')?.textContent.startsWith('horse ·'));

  step = 'playing a preview';
  await hits.first().locator('button.preview-button').click();
  await plays(hits.first().locator('.viewer'), 'library-preview');

  step = 'opening a clip\'s details';
  const clipId = await hits.first().getAttribute('data-clip');
  const clip = await (await page.request.get(`${args.base}/v1/clips/${clipId}`)).json();
  const skeleton = await (await page.request.get(`${args.base}/v1/skeletons/${clip.skeleton_id}`)).json();
  await hits.first().locator('button.details-button').click();
  await page.waitForSelector('#clip-detail .viewer canvas');
  await page.waitForFunction((id) => document.getElementById('detail-title').textContent.startsWith(`Clip ${id}:`), clipId);
  const licence = await page.locator('#clip-detail .facts dt:text-is("Licence") + dd').textContent();
  check(licence === clip.licence, `the licence shown is ${licence}, not the clip's ${clip.licence}`);
  const captions = await page.locator('#clip-detail .captions li').allTextContents();
  check(JSON.stringify(captions) === JSON.stringify(clip.captions), `the captions shown are ${captions}, not ${clip.captions}`);
  report.joints = await page.locator('#clip-detail .tree li').count();
  check(report.joints === skeleton.joints, `the tree shows ${report.joints} joints; the skeleton has ${skeleton.joints}`);
  await page.screenshot({ path: join(args.out, 'library.png') });

  step = 'finding similar clips';
  await page.click('#clip-detail .find-similar');
  await page.waitForFunction(() => document.getElementById('results-title').textContent.startsWith('Clips like clip'));
  await page.waitForSelector('#results .hit');
  report.similar = await page.locator('#results .hit').count();

  step = 'transferring a clip to another skeleton';
  await page.click('#clip-detail .to-transfer');
  await page.waitForSelector('#view-transfer:not([hidden])');
  const target = await page.locator('#transfer-skeleton-id option').evaluateAll(
    (options, own) => options.map((o) => o.value).find((v) => v !== own), String(clip.skeleton_id));
  await page.selectOption('#transfer-skeleton-id', target);
  await page.click('#transfer-button');
  await page.waitForFunction(() => document.querySelectorAll('#transfer-results .viewer canvas').length === 2);
  await plays(page.locator('#transfer-results .viewer').nth(1), 'transfer-result');
  await page.screenshot({ path: join(args.out, 'transfer.png') });

  check(!errors.length, errors.join('\n'));
  step = 'done';
  console.log(JSON.stringify(report));
} catch (e) {
  console.error(`web page test failed while ${step}: ${e.message}`);
  if (errors.length) console.error(errors.join('\n'));
  console.error(JSON.stringify(report));
  process.exitCode = 1;
} finally {
  await browser.close();
}
