// Screenshot of the viewer with every query tool's overlay drawn: node dev/ui_shot.mjs URL PNG
import puppeteer from 'puppeteer-core';
const [url, out] = process.argv.slice(2);
const browser = await puppeteer.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-sandbox', '--ignore-gpu-blocklist'] });
const page = await browser.newPage();
page.on('pageerror', (e) => console.log('pageerror:', e.message));
await page.setViewport({ width: 900, height: 560 });
await page.goto(url);
await page.waitForFunction('window.smrdbViewer && (window.smrdbViewer.ready || window.smrdbViewer.error)');
console.log(await page.evaluate(async () => {
  const sv = window.smrdbViewer, v = sv.viewer, o = v.frame.origin, b = v.bounds;
  await sv.waitIdle(30000);
  const w = 0.3 * (b.max[0] - b.min[0]);
  await v.overlay.contours(Number(document.getElementById('interval').value));
  await v.overlay.profile([o[0] - w, o[1] - w / 2], [o[0] + w, o[1] + w / 2]);
  const e = await v.overlay.elevation([o[0] + w / 2, o[1] - w / 2]);
  await v.overlay.los([o[0] - w, o[1] + w, b.max[2]], [e.x, e.y, e.z + 2]);
  await new Promise((r) => setTimeout(r, 400));
  return JSON.stringify(sv.stats[sv.stats.length - 1]);
}));
await page.screenshot({ path: out });
await browser.close();
