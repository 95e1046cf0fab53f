// Screenshot rerun's web viewer in headless Chromium once it has really drawn the recording.
//
//   node docs/screenshot/shoot.mjs URL OUT.png [WIDTH HEIGHT TIMEOUT_S]
//
// The viewer is WebAssembly drawing into one canvas, so nothing in the DOM says "loaded". Every
// two seconds we take a screenshot and measure, inside the page, the share of strongly coloured
// pixels (rerun's own interface is grey; clusters and images are coloured). The screenshot is
// kept once that share has grown past MIN_COLOURED and stayed the same for three polls in a row
// (images decode after the 3D views draw); if that never happens
// before the timeout, the last screenshot is written anyway and the exit status is 1.
// Chromium: /usr/bin/chromium (Debian's package) or $CHROMIUM.
import { writeFileSync } from "node:fs";
import { chromium } from "playwright-core";

const [url, out, width = "1600", height = "1000", timeoutS = "240"] = process.argv.slice(2);
if (!url || !out) {
  console.error("usage: node shoot.mjs URL OUT.png [WIDTH HEIGHT TIMEOUT_S]");
  process.exit(2);
}
const MIN_COLOURED = 0.01;
const STABLE = 0.05; // relative change between two polls still counted as "stopped changing"

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  // software WebGL: headless machines have no GPU
  args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--ignore-gpu-blocklist"],
});
let status = 1;
try {
  const page = await browser.newPage({
    viewport: { width: Number(width), height: Number(height) },
    deviceScaleFactor: 1,
  });
  page.on("pageerror", (error) => console.error(`page error: ${error.message}`));
  await page.goto(url, { waitUntil: "load" });
  await page.waitForSelector("canvas", { timeout: Number(timeoutS) * 1000 });

  const deadline = Date.now() + Number(timeoutS) * 1000;
  let shot = null;
  const recent = [];
  while (Date.now() < deadline) {
    await page.waitForTimeout(2000);
    try {
      // software rendering on a busy machine can take long for one frame
      shot = await page.screenshot({ timeout: 120_000 });
    } catch (error) {
      console.error(`screenshot failed, trying again: ${error.message.split("\n")[0]}`);
      continue;
    }
    const coloured = await page.evaluate(async (base64) => {
      const blob = await (await fetch(`data:image/png;base64,${base64}`)).blob();
      const bitmap = await createImageBitmap(blob);
      const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
      const context = canvas.getContext("2d");
      context.drawImage(bitmap, 0, 0);
      const pixels = context.getImageData(0, 0, bitmap.width, bitmap.height).data;
      let count = 0;
      for (let i = 0; i < pixels.length; i += 4) {
        const r = pixels[i], g = pixels[i + 1], b = pixels[i + 2];
        if (Math.max(r, g, b) - Math.min(r, g, b) > 60) count += 1;
      }
      return count / (pixels.length / 4);
    }, shot.toString("base64"));
    console.error(`coloured pixels: ${(100 * coloured).toFixed(2)} %`);
    recent.push(coloured);
    const last = recent.slice(-3);
    if (last.length === 3 && Math.min(...last) >= MIN_COLOURED
        && Math.max(...last) - Math.min(...last) <= STABLE * Math.min(...last)) {
      status = 0;
      break;
    }
  }
  if (shot) writeFileSync(out, shot);
  if (status !== 0) console.error("the viewer never showed stable coloured content; last screenshot kept");
} finally {
  await browser.close();
}
process.exit(status);
