import puppeteer from 'puppeteer-core';
const [url, out] = process.argv.slice(2);
const browser = await puppeteer.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-sandbox', '--ignore-gpu-blocklist'] });
const page = await browser.newPage();
page.on('pageerror', (e) => console.log('pageerror:', e.message));
page.on('console', (m) => m.type() === 'error' && console.log('console:', m.text()));
await page.setViewport({ width: 640, height: 400 });
const t0 = Date.now();
await page.goto(url);
await page.waitForFunction('window.smrdbCesium && (window.smrdbCesium.failed || (window.smrdbCesium.ready && window.smrdbCesium.tilesLoaded > 0))', { timeout: 60000 }).catch(e => console.log('timeout', e.message));
console.log(await page.evaluate(() => JSON.stringify({ l: smrdbCesium.tilesLoaded, r: smrdbCesium.tilesRequested, e: smrdbCesium.errors, p: smrdbCesium.pending })), (Date.now()-t0)/1000, 's');
await page.screenshot({ path: out });
await browser.close();
