import puppeteer from 'puppeteer-core';
const url = process.argv[2], out = process.argv[3];
const browser = await puppeteer.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-sandbox', '--ignore-gpu-blocklist'] });
const page = await browser.newPage();
page.on('console', (m) => console.log('console:', m.type(), m.text()));
page.on('pageerror', (e) => console.log('pageerror:', e.message));
await page.setViewport({ width: 640, height: 400 });
await page.goto(url);
await page.waitForFunction('window.smrdbViewer && (window.smrdbViewer.ready || window.smrdbViewer.error)', { timeout: 20000 });
const r = await page.evaluate(async () => {
  const v = window.smrdbViewer;
  if (v.error) return v.error;
  await v.waitIdle(20000);
  return { stats: v.stats.map(s => [s.frame, s.triangles, s.drawn, s.morph_triangles, s.update_ms.toFixed(1)]), held: v.held(), cam: v.camera() };
});
console.log(JSON.stringify(r));
await page.screenshot({ path: out });
await browser.close();
