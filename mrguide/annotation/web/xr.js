// WebXR: the same scene in a headset.
//
// - Quest 3 (and any device that offers it): `immersive-ar` with passthrough. Without a marker
//   registration the robot base is placed on a surface by hit-test: a reticle follows the surface
//   in front of the person, the first select puts the base there, facing them.
// - HoloLens 2 (no immersive-ar in its browser) and VR headsets: `immersive-vr`. HoloLens reports
//   the 'additive' environment blend mode: the background is rendered transparent (black adds no
//   light), so only the twin is seen over the real cell.
// - With `registration.T_base_hmd` in the server's hello (written by `mrguide calibrate`: the HMD's
//   tracking frame in the robot base frame) the scene is placed with its inverse and no hit-test is
//   needed: the twin's base sits on the real robot's base.
// - In the session a controller or hand `select` marks the waypoint at the controller's tip (the
//   pinch point for a hand), converted to the robot frame, clamped into the workspace box, and
//   submits it with the current vacuum setting. A controller held outside the workspace points instead:
//   where its ray meets the part, the goal or the table places the target as a desktop click does.
//   `squeeze` toggles the vacuum while a request is open; with none open it steps in (as the page's
//   Intervene button).

import * as THREE from 'three';
import { DESKTOP_ROOT, COLORS } from './scene.js';

const DEFAULT_DISTANCE = 0.8; // m in front of the person, when neither registration nor hit-test places the base
const DEFAULT_DROP = 0.7; // m below the eyes (about a table)

export class XRView {
  /**
   * @param view TwinView
   * @param hooks {onSelectPoint(robotPoint, on) -> void, pickRay(raycaster) -> {point, on}|null, onSqueeze() -> void, onPresenting(bool) -> void,
   *               label() -> string[] (lines for the in-headset panel)}
   */
  constructor(view, hooks) {
    this.view = view;
    this.hooks = hooks;
    this.registration = null;
    this.session = null;
    this.info = {
      available: false, arSupported: false, vrSupported: false, message: 'checking for WebXR...',
      mode: null, blendMode: null, presenting: false, transparent: false, referenceSpace: null,
      placed: false, placementSource: null, hitTest: false, reticleVisible: false,
      selects: 0, squeezes: 0, lastSelect: null, error: null, frames: 0,
    };
    this._buildProps();
  }

  _buildProps() {
    const scene = this.view.scene;
    this.reticle = new THREE.Mesh(new THREE.RingGeometry(0.06, 0.08, 40).rotateX(-Math.PI / 2),
      new THREE.MeshBasicMaterial({ color: COLORS.target, side: THREE.DoubleSide }));
    this.reticle.matrixAutoUpdate = false;
    this.reticle.visible = false;
    scene.add(this.reticle);

    // A pen tip on each controller (three.js keeps the target-ray groups posed): what a select marks.
    this.pens = [0, 1].map((i) => {
      const ray = this.view.renderer.xr.getController(i);
      const tip = new THREE.Mesh(new THREE.SphereGeometry(0.008, 16, 12), new THREE.MeshBasicMaterial({ color: COLORS.target }));
      const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), new THREE.Vector3(0, 0, -0.25)]),
        new THREE.LineBasicMaterial({ color: 0xffffff, transparent: true, opacity: 0.5 }));
      ray.add(tip, line);
      ray.visible = false;
      scene.add(ray);
      return ray;
    });

    // A text panel that faces the person: phase, what is asked, vacuum, training status.
    const canvas = document.createElement('canvas');
    canvas.width = 1024;
    canvas.height = 384;
    this.panelCanvas = canvas;
    this.panelTexture = new THREE.CanvasTexture(canvas);
    this.panelTexture.colorSpace = THREE.SRGBColorSpace;
    this.panel = new THREE.Mesh(new THREE.PlaneGeometry(0.48, 0.18),
      new THREE.MeshBasicMaterial({ map: this.panelTexture, transparent: true, depthWrite: false, depthTest: false }));
    this.panel.renderOrder = 10; // always readable
    this.panel.visible = false;
    scene.add(this.panel);
  }

  /** Which immersive modes the browser (or the emulator) offers; returns the info. */
  async detect() {
    if (!('xr' in navigator) || !navigator.xr) {
      Object.assign(this.info, { available: false,
        message: window.isSecureContext ? 'No WebXR in this browser: open the page in the headset\'s browser.'
          : 'WebXR needs a secure context: use https (--cert/--key) or localhost (adb reverse).' });
      return this.info;
    }
    const ask = async (mode) => { try { return await navigator.xr.isSessionSupported(mode); } catch { return false; } };
    this.info.arSupported = await ask('immersive-ar');
    this.info.vrSupported = await ask('immersive-vr');
    this.info.available = this.info.arSupported || this.info.vrSupported;
    this.info.message = this.info.arSupported ? 'Mixed reality (immersive-ar) available.'
      : this.info.vrSupported ? 'No immersive-ar here: immersive-vr is used (HoloLens 2 blends it additively).'
        : 'No headset found: WebXR is present but offers no immersive session.';
    return this.info;
  }

  setRegistration(reg) {
    this.registration = reg && Array.isArray(reg.T_base_hmd) ? reg : null;
  }

  async enter() {
    if (this.session) return this.info;
    if (!this.info.available) throw new Error(this.info.message);
    const mode = this.info.arSupported ? 'immersive-ar' : 'immersive-vr';
    const optionalFeatures = ['local-floor', 'hand-tracking'];
    if (mode === 'immersive-ar' && !this.registration) optionalFeatures.push('hit-test');
    const session = await navigator.xr.requestSession(mode, { optionalFeatures });
    this.session = session;
    const enabled = session.enabledFeatures || ['local-floor'];
    const refType = enabled.includes('local-floor') ? 'local-floor' : 'local';
    const r = this.view.renderer;
    r.xr.setReferenceSpaceType(refType);
    await r.xr.setSession(session);
    const blend = session.environmentBlendMode || (mode === 'immersive-ar' ? 'alpha-blend' : 'opaque');
    Object.assign(this.info, { mode, blendMode: blend, presenting: true, referenceSpace: refType, placed: false,
      placementSource: null, hitTest: false, reticleVisible: false, error: null });
    this._setTransparent(blend !== 'opaque');
    this.view.root.visible = false; // until placed: no twin under the person's feet
    this.view.gizmo.getHelper().visible = false; // the mouse gizmo is for the desktop camera; here a select marks
    this.pens.forEach((p) => { p.visible = true; });
    this.panel.visible = true;

    session.addEventListener('select', (e) => this._onSelect(e));
    session.addEventListener('squeeze', () => { this.info.squeezes += 1; this.hooks.onSqueeze(); });
    session.addEventListener('end', () => this._onEnd());

    if (this.registration) {
      this._place(new THREE.Matrix4().fromArray(this.registration.T_base_hmd.flat()).transpose().invert(), 'registration');
    } else if (mode === 'immersive-ar' && enabled.includes('hit-test')) {
      try {
        const viewer = await session.requestReferenceSpace('viewer');
        this.hitSource = await session.requestHitTestSource({ space: viewer });
        this.info.hitTest = true;
      } catch (err) {
        this.info.error = `hit-test unavailable (${err.message}): the base is placed in front of you`;
      }
    }
    r.setAnimationLoop((t, frame) => this._frame(frame));
    this.hooks.onPresenting(true);
    return this.info;
  }

  async exit() {
    if (this.session) await this.session.end();
  }

  _setTransparent(transparent) {
    const v = this.view;
    this.info.transparent = transparent;
    if (transparent) {
      v.scene.background = null;
      v.renderer.setClearColor(0x000000, 0);
    } else {
      v.scene.background = new THREE.Color(COLORS.background);
      v.renderer.setClearColor(COLORS.background, 1);
    }
    // Over the real cell the real table is there; in opaque VR keep the virtual one.
    v.tableGroup.forEach((o) => { o.visible = !transparent; });
  }

  /** Place the robot base frame in the XR reference space (matrix: robot frame -> three world). */
  _place(matrix, source) {
    const root = this.view.root;
    root.matrix.copy(matrix);
    root.matrixWorldNeedsUpdate = true;
    root.updateMatrixWorld(true);
    root.visible = true;
    Object.assign(this.info, { placed: true, placementSource: source });
    this.reticle.visible = false;
    this.info.reticleVisible = false;
    if (this.hitSource) { this.hitSource.cancel(); this.hitSource = null; }
  }

  /** Base at `point` (world, on a surface), robot +x pointing at the person: the workspace lies between. */
  _placeFacingViewer(point, source) {
    const head = this.head ? this.head.clone() : this.view.renderer.xr.getCamera().getWorldPosition(new THREE.Vector3());
    const d = head.sub(point);
    d.y = 0;
    if (d.lengthSq() < 1e-6) d.set(0, 0, 1);
    d.normalize();
    const yaw = Math.atan2(-d.z, d.x);
    const m = new THREE.Matrix4().makeTranslation(point.x, point.y, point.z)
      .multiply(new THREE.Matrix4().makeRotationY(yaw)).multiply(DESKTOP_ROOT);
    this._place(m, source);
  }

  _frame(frame) {
    const r = this.view.renderer;
    this.info.frames += 1;
    const ref = r.xr.getReferenceSpace();
    const viewerPose = frame && ref ? frame.getViewerPose(ref) : null;
    if (viewerPose) { // the head (between the eyes), for turning the robot and the panel to the person
      const p = viewerPose.transform.position;
      this.head = new THREE.Vector3(p.x, p.y, p.z);
    }
    if (frame && !this.info.placed) {
      if (this.hitSource) {
        const hits = frame.getHitTestResults(this.hitSource);
        const pose = hits.length ? hits[0].getPose(ref) : null;
        this.reticle.visible = !!pose;
        if (pose) this.reticle.matrix.fromArray(pose.transform.matrix);
        this.info.reticleVisible = !!pose;
      } else if (!this.info.hitTest) {
        const viewer = viewerPose;
        if (viewer) {
          const p = viewer.transform.position;
          const o = viewer.transform.orientation;
          const fwd = new THREE.Vector3(0, 0, -1).applyQuaternion(new THREE.Quaternion(o.x, o.y, o.z, o.w));
          fwd.y = 0;
          if (fwd.lengthSq() < 1e-6) fwd.set(0, 0, -1);
          fwd.normalize();
          const spot = new THREE.Vector3(p.x, p.y - DEFAULT_DROP, p.z).addScaledVector(fwd, DEFAULT_DISTANCE);
          this._placeFacingViewer(spot, 'default');
        }
      }
    }
    this._updatePanel();
    this.view.render();
  }

  _updatePanel() {
    const lines = this.hooks.label();
    const key = lines.join('\n');
    if (key !== this._panelKey) {
      this._panelKey = key;
      const c = this.panelCanvas.getContext('2d');
      c.clearRect(0, 0, 1024, 384);
      c.fillStyle = 'rgba(16,20,27,0.82)';
      c.beginPath();
      c.roundRect(0, 0, 1024, 384, 28);
      c.fill();
      c.fillStyle = '#ffd23f';
      c.font = 'bold 46px system-ui, sans-serif';
      c.fillText(lines[0] || '', 36, 70);
      c.fillStyle = '#e8edf3';
      c.font = '34px system-ui, sans-serif';
      wrap(c, lines[1] || '', 36, 126, 950, 42, 4);
      c.fillStyle = '#9fb0c3';
      c.font = '30px system-ui, sans-serif';
      c.fillText(lines[2] || '', 36, 350);
      this.panelTexture.needsUpdate = true;
    }
    // Beside the workspace (robot -y side), turned to the person: it never hides the arm or the target.
    const { lo, hi } = this.view.workspace;
    this.panel.position.copy(this.view.toWorld([(lo[0] + hi[0]) / 2, lo[1] - 0.3, hi[2]]));
    const cam = this.head || this.view.renderer.xr.getCamera().getWorldPosition(new THREE.Vector3());
    this.panel.lookAt(cam.x, this.panel.position.y, cam.z);
  }

  _onSelect(event) {
    this.info.selects += 1;
    if (!this.info.placed) {
      if (this.reticle.visible) {
        const p = new THREE.Vector3().setFromMatrixPosition(this.reticle.matrix);
        this._placeFacingViewer(p, 'hit-test');
      }
      return; // the first select places the robot; the next ones mark
    }
    const ref = this.view.renderer.xr.getReferenceSpace();
    const source = event.inputSource;
    const world = pointOf(event.frame, source, ref);
    if (!world) return;
    const local = this.view.root.worldToLocal(world.clone());
    let robot = [local.x, local.y, local.z];
    let on = null;
    // A controller held outside the workspace points: its ray places the target as a desktop click does.
    const { lo, hi } = this.view.workspace;
    if (!source.hand && robot.some((v, i) => v < lo[i] || v > hi[i])) {
      const ray = rayOf(event.frame, source, ref);
      const picked = ray && this.hooks.pickRay(ray);
      if (picked) ({ point: robot, on } = picked);
    }
    this.info.lastSelect = { world: [world.x, world.y, world.z], robot, hand: !!source.hand, on };
    this.hooks.onSelectPoint(robot, on);
  }

  _onEnd() {
    const v = this.view;
    v.renderer.setAnimationLoop(null);
    this.session = null;
    this.hitSource = null;
    this.head = null;
    this.reticle.visible = false;
    this.panel.visible = false;
    this.pens.forEach((p) => { p.visible = false; });
    v.root.matrix.copy(DESKTOP_ROOT);
    v.root.matrixWorldNeedsUpdate = true;
    v.root.visible = true;
    v.gizmo.getHelper().visible = v.gizmo.enabled;
    this._setTransparent(false);
    Object.assign(this.info, { presenting: false, mode: null, blendMode: null, placed: false, placementSource: null,
      reticleVisible: false });
    this.hooks.onPresenting(false);
    v.resize();
    v.requestRender();
  }
}

/** Where a select marks: a hand's pinch point (thumb and index tips), else the target ray's origin. */
function pointOf(frame, source, ref) {
  if (!frame) return null;
  if (source.hand && frame.getJointPose) {
    const a = source.hand.get('index-finger-tip');
    const b = source.hand.get('thumb-tip');
    const pa = a && frame.getJointPose(a, ref);
    const pb = b && frame.getJointPose(b, ref);
    if (pa && pb) {
      const x = pa.transform.position;
      const y = pb.transform.position;
      return new THREE.Vector3((x.x + y.x) / 2, (x.y + y.y) / 2, (x.z + y.z) / 2);
    }
  }
  const pose = frame.getPose(source.targetRaySpace, ref);
  if (!pose) return null;
  const p = pose.transform.position;
  return new THREE.Vector3(p.x, p.y, p.z);
}

/** A controller's target ray (its pose's -z axis) as a raycaster in the reference space. */
function rayOf(frame, source, ref) {
  const pose = frame && frame.getPose(source.targetRaySpace, ref);
  if (!pose) return null;
  const m = new THREE.Matrix4().fromArray(pose.transform.matrix);
  const origin = new THREE.Vector3().setFromMatrixPosition(m);
  const dir = new THREE.Vector3(0, 0, -1).transformDirection(m);
  return new THREE.Raycaster(origin, dir);
}

function wrap(ctx, text, x, y, width, lineHeight, maxLines) {
  const words = text.split(/\s+/);
  let line = '';
  let n = 0;
  for (const w of words) {
    const next = line ? `${line} ${w}` : w;
    if (ctx.measureText(next).width > width && line) {
      ctx.fillText(line, x, y + n * lineHeight);
      n += 1;
      line = w;
      if (n >= maxLines) return;
    } else {
      line = next;
    }
  }
  if (line && n < maxLines) ctx.fillText(line, x, y + n * lineHeight);
}
