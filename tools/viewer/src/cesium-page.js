// The CesiumJS page (cesium.html): smrdb's quantized-mesh tiles through Cesium's own
// CesiumTerrainProvider, no smrdb code in the loop. Offline: a grid instead of imagery, no ion.
/* global Cesium */
(async function main() {
  const params = new URLSearchParams(location.search);
  const status = document.getElementById('status');
  const state = { tilesRequested: 0, tilesLoaded: 0, errors: [], ready: false };
  window.smrdbCesium = state;
  try {
    let db = params.get('db');
    if (!db) {
      const dbs = await (await fetch('v1/databases')).json();
      db = (dbs.find((d) => d.kind === 'terrain') || {}).name;
      if (!db) throw new Error('no terrain database is served');
    }
    const info = await (await fetch(`v1/${encodeURIComponent(db)}/info`)).json();
    const root = new URL(`v1/${encodeURIComponent(db)}/`, location.href).href;
    // requestMetadata: false. smrdb's tiles carry the metadata extension ({"geometricError"})
    // while layer.json has no "metadataAvailability"; Cesium 1.145 then fails on every tile
    // (layer.availabilityTilesLoaded is undefined). Not asking for the extension skips it.
    const terrain = await Cesium.CesiumTerrainProvider.fromUrl(root, { requestVertexNormals: true, requestMetadata: false });
    terrain.errorEvent.addEventListener((e) => state.errors.push(String(e.message || e)));
    const viewer = new Cesium.Viewer('cesium', {
      terrainProvider: terrain,
      baseLayer: new Cesium.ImageryLayer(new Cesium.GridImageryProvider({})),
      baseLayerPicker: false, geocoder: false, timeline: false, animation: false, homeButton: false,
      sceneModePicker: false, navigationHelpButton: false, fullscreenButton: false, infoBox: false,
      selectionIndicator: false,
    });
    viewer.scene.verticalExaggeration = Number(params.get('exag') || 2);
    viewer.scene.globe.enableLighting = false;
    const b = info.bounds;
    const rect = Cesium.Rectangle.fromDegrees(b.min[0], b.min[1], b.max[0], b.max[1]);
    const c = Cesium.Rectangle.center(rect);
    const span = Math.max(b.max[0] - b.min[0], b.max[1] - b.min[1]) * 111000;
    viewer.camera.setView({
      destination: Cesium.Cartesian3.fromRadians(c.longitude, c.latitude - (0.9 * span) / 6371000, b.max[2] + 0.6 * span),
      orientation: { heading: 0, pitch: Cesium.Math.toRadians(-35), roll: 0 },
    });
    const globe = viewer.scene.globe;
    globe.tileLoadProgressEvent.addEventListener((pending) => {
      state.pending = pending;
      if (pending === 0) state.ready = true;
    });
    const original = terrain.requestTileGeometry.bind(terrain);
    terrain.requestTileGeometry = (x, y, level, request) => {
      const p = original(x, y, level, request);
      if (p) {
        ++state.tilesRequested;
        p.then(() => ++state.tilesLoaded, (e) => state.errors.push(`tile ${level}/${x}/${y}: ${e}`));
      }
      return p;
    };
    state.viewer = viewer;
    const tick = () => {
      status.textContent = `${db}: quantized-mesh tiles through CesiumTerrainProvider\n` +
        `tiles loaded ${state.tilesLoaded} / requested ${state.tilesRequested}, pending ${state.pending ?? '-'}` +
        (state.errors.length ? `\nerrors: ${state.errors.slice(-2).join('; ')}` : '');
      setTimeout(tick, 250);
    };
    tick();
  } catch (e) {
    status.textContent = `error: ${e.message || e}`;
    state.errors.push(String(e.message || e));
    state.failed = true;
  }
})();
