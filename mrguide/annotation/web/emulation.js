// WebXR emulation for tests and demos without a headset: Meta's IWER (npm `iwer`).
//
// Loaded only when the page URL carries `?xr=PROFILE` (see app.js); a normal page never imports it.
// PROFILE is one of:
//   quest3     IWER's Meta Quest 3 profile: immersive-ar with hit-test, Touch Plus controllers.
//   quest3-vr  the same headset without immersive-ar (VR only), to exercise the fallback.
//   hololens2  a HoloLens 2-like profile written here (IWER ships none): immersive-vr only, the
//              'additive' environment blend mode of a see-through display, hand input only.
//
// Hit-test in IWER needs a "synthetic environment module" (SEM) that answers the rays. Meta's
// @iwer/sem loads captured rooms (megabytes, plus its own copy of three.js); a table is all this page
// needs, so `TableEnvironment` below implements IWER's SEM interface (computeHitTestResults, render,
// trackedPlanes/trackedMeshes, environmentCanvas, computeDepthBuffer) with one horizontal surface.
// IWER's own hit-test machinery (XRHitTestSource, XRHitTestResult.getPose) is what the page uses.

import { XRDevice, metaQuest3 } from 'iwer';

/** Height of the emulated table surface in the XR reference space (local-floor: y up, metres). */
export const TABLE_HEIGHT = 0.75;

const hololens2 = {
  name: 'HoloLens 2 (emulated profile)',
  controllerConfig: undefined,
  supportedSessionModes: ['inline', 'immersive-vr'],
  supportedFeatures: ['viewer', 'local', 'local-floor', 'unbounded', 'hand-tracking'],
  supportedFrameRates: [60],
  isSystemKeyboardSupported: true,
  internalNominalFrameRate: 60,
  environmentBlendModes: { 'immersive-vr': 'additive' },
  interactionMode: 'world-space',
  userAgent: 'Mozilla/5.0 (Windows NT 10.0; ARM 64; HoloLens 2) AppleWebKit/537.36 (KHTML, like Gecko) Chrome/120.0.0.0 Safari/537.36 Edg/120.0.0.0',
};

const quest3VrOnly = {
  ...metaQuest3,
  name: 'Meta Quest 3 (VR only)',
  supportedSessionModes: ['inline', 'immersive-vr'],
  supportedFeatures: metaQuest3.supportedFeatures.filter((f) => f !== 'hit-test'),
};

export const PROFILES = { quest3: metaQuest3, 'quest3-vr': quest3VrOnly, hololens2 };

/** IWER's SEM interface with one infinite horizontal surface at TABLE_HEIGHT (y up). */
class TableEnvironment {
  constructor() { // IWER passes the XRDevice; a table does not need it
    this.version = 'mrguide-table-1';
    this.height = TABLE_HEIGHT;
    this.trackedPlanes = new Set();
    this.trackedMeshes = new Set();
    this.planesVisible = false;
    this.boundingBoxesVisible = false;
    this.meshesVisible = false;
    // What the emulated passthrough camera "sees" behind the app canvas: a plain room.
    const canvas = document.createElement('canvas');
    canvas.width = 64;
    canvas.height = 64;
    canvas.style.position = 'absolute';
    canvas.style.inset = '0';
    canvas.style.width = '100%';
    canvas.style.height = '100%';
    const ctx = canvas.getContext('2d');
    const g = ctx.createLinearGradient(0, 0, 0, 64);
    g.addColorStop(0, '#8a8f96');
    g.addColorStop(0.55, '#6d6258');
    g.addColorStop(1, '#4a4038');
    ctx.fillStyle = g;
    ctx.fillRect(0, 0, 64, 64);
    this.environmentCanvas = canvas;
  }

  render() {}

  loadEnvironment() {}

  loadDefaultEnvironment() { return Promise.resolve(); }

  deleteAll() {}

  computeDepthBuffer() { return null; }

  /** Hits of a ray (origin = translation, direction = -z of the column-major 4x4) with the table. */
  computeHitTestResults(m) {
    const o = [m[12], m[13], m[14]];
    const d = [-m[8], -m[9], -m[10]];
    if (Math.abs(d[1]) < 1e-9) return [];
    const t = (this.height - o[1]) / d[1];
    if (!(t > 0)) return [];
    const hit = new Float32Array(16);
    hit[0] = 1; hit[5] = 1; hit[10] = 1; hit[15] = 1; // y axis = surface normal (up)
    hit[12] = o[0] + t * d[0];
    hit[13] = this.height;
    hit[14] = o[2] + t * d[2];
    return [hit];
  }
}

/**
 * Install IWER's emulated runtime over navigator.xr (also when the browser has its own) and return
 * the XRDevice, which tests drive: device.position/quaternion (the head), device.controllers.right,
 * device.hands.right, device.primaryInputMode.
 */
export function installEmulatedXR(profileName) {
  const config = PROFILES[profileName];
  if (!config) throw new Error(`unknown XR emulation profile '${profileName}': use ${Object.keys(PROFILES).join(', ')}`);
  const device = new XRDevice(config, { stereoEnabled: false });
  if (config.supportedFeatures.includes('hit-test')) {
    device.installSEM(TableEnvironment);
  }
  if (!config.controllerConfig) device.primaryInputMode = 'hand';
  device.installRuntime({ forceInstall: true });
  return device;
}
