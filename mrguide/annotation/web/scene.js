// The twin view: the arm, the object, the goal, the workspace box and the target gizmo, in the
// robot base frame (z up, metres). Everything robot-related hangs under `root`, a group that maps the
// robot frame into three.js's world (y up). On the desktop `root` is a fixed rotation; in a headset
// xr.js replaces its matrix with the placement (marker registration, hit-test or a default spot).

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { TransformControls } from 'three/addons/controls/TransformControls.js';
import URDFLoader from 'urdf-loader';

export const COLORS = {
  background: 0x10141b,
  table: 0x1b222c,
  grid: 0x2a3442,
  workspace: 0x4f8bd6,
  object: 0xe08a2e,
  goal: 0x3fbf7f,
  tcp: 0x49c6e5,
  target: 0xffd23f,
  previous: 0xd45bd0,
};

/** Resolution of a target: 0.1 mm, so the numbers shown are exactly the numbers sent. */
export const TARGET_RESOLUTION = 1e-4;

/** Maps the robot base frame (z up) to three.js's world (y up): a rotation of -90 degrees about x. */
export const DESKTOP_ROOT = new THREE.Matrix4().makeRotationX(-Math.PI / 2);

const v3 = (p) => new THREE.Vector3(p[0], p[1], p[2]);

export function roundTarget(p) {
  return p.map((v) => Math.round(v / TARGET_RESOLUTION) * TARGET_RESOLUTION).map((v) => Number(v.toFixed(4)));
}

export class TwinView extends EventTarget {
  constructor(container) {
    super();
    this.container = container;
    this.frames = 0;
    this.workspace = { lo: [0.3, -0.2, 0.045], hi: [0.65, 0.4, 0.35] };
    this.robot = null;
    this.robotState = { loading: false, loaded: false, error: null, meshErrors: 0 };
    this.jointNames = [];
    this.pendingJoints = null;

    const renderer = new THREE.WebGLRenderer({ antialias: true, alpha: true });
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    renderer.setClearColor(COLORS.background, 1);
    renderer.xr.enabled = true;
    renderer.domElement.id = 'viewport-canvas';
    container.appendChild(renderer.domElement);
    this.renderer = renderer;

    const scene = new THREE.Scene();
    scene.background = new THREE.Color(COLORS.background);
    this.scene = scene;
    this.camera = new THREE.PerspectiveCamera(42, 1, 0.01, 40);

    scene.add(new THREE.HemisphereLight(0xdfe8ff, 0x202830, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 2.2);
    sun.position.set(1.5, 3, 2);
    scene.add(sun);

    this.root = new THREE.Group();
    this.root.name = 'robot-base-frame';
    this.root.matrixAutoUpdate = false;
    this.root.matrix.copy(DESKTOP_ROOT);
    scene.add(this.root);

    this._buildStatic();
    this._buildMarkers();

    this.orbit = new OrbitControls(this.camera, renderer.domElement);
    this.orbit.enableDamping = false;
    this.orbit.addEventListener('change', () => this.requestRender());

    const gizmo = new TransformControls(this.camera, renderer.domElement);
    gizmo.setMode('translate');
    gizmo.setSpace('local'); // the target's local axes are the robot frame's
    gizmo.size = 0.9;
    gizmo.attach(this.target);
    gizmo.addEventListener('dragging-changed', (e) => {
      this.orbit.enabled = !e.value;
      if (e.value) this.dispatchEvent(new Event('interact'));
      else this._targetMoved(true);
    });
    gizmo.addEventListener('objectChange', () => this._targetMoved(false));
    gizmo.addEventListener('change', () => this.requestRender());
    scene.add(gizmo.getHelper());
    this.gizmo = gizmo;

    this.resetCamera();
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  // -- building ---------------------------------------------------------------------------------
  _buildStatic() {
    const table = new THREE.Mesh(
      new THREE.PlaneGeometry(1.8, 1.6),
      new THREE.MeshStandardMaterial({ color: COLORS.table, roughness: 0.95, metalness: 0 }),
    );
    table.position.set(0.35, 0.1, -0.001);
    table.name = 'table';
    this.root.add(table);
    const grid = new THREE.GridHelper(1.6, 16, COLORS.grid, COLORS.grid);
    grid.rotation.x = Math.PI / 2; // GridHelper lies in xz; the table is the robot's xy plane
    grid.position.set(0.35, 0.1, 0);
    grid.name = 'grid';
    this.root.add(grid);
    this.tableGroup = [table, grid];
    const axes = new THREE.AxesHelper(0.12);
    axes.name = 'base-axes';
    this.root.add(axes);

    this.workspaceBox = new THREE.LineSegments(
      new THREE.EdgesGeometry(new THREE.BoxGeometry(1, 1, 1)),
      new THREE.LineBasicMaterial({ color: COLORS.workspace, transparent: true, opacity: 0.9 }),
    );
    this.workspaceBox.name = 'workspace';
    this.root.add(this.workspaceBox);
    this.workspaceFloor = new THREE.Mesh(
      new THREE.PlaneGeometry(1, 1),
      new THREE.MeshBasicMaterial({ color: COLORS.workspace, transparent: true, opacity: 0.08, depthWrite: false }),
    );
    this.root.add(this.workspaceFloor);
  }

  _buildMarkers() {
    const std = (color, extra = {}) => new THREE.MeshStandardMaterial({ color, roughness: 0.55, metalness: 0.05, ...extra });

    this.object = new THREE.Group(); // the part: its boxes (`setPart`), about its origin
    this.object.name = 'object';
    this.object.visible = false;
    this.objectMaterial = std(COLORS.object);
    this.root.add(this.object);

    this.goal = new THREE.Group();
    this.goal.name = 'goal';
    const ring = new THREE.Mesh(new THREE.RingGeometry(0.028, 0.036, 48),
      new THREE.MeshBasicMaterial({ color: COLORS.goal, side: THREE.DoubleSide }));
    this.goalRing = ring;
    this.goalGhost = new THREE.LineSegments(new THREE.EdgesGeometry(new THREE.BoxGeometry(1, 1, 1)),
      new THREE.LineBasicMaterial({ color: COLORS.goal, transparent: true, opacity: 0.8 }));
    // what a click on the goal hits: a disc as wide as the ring, drawn fully transparent
    this.goalDisc = new THREE.Mesh(new THREE.CircleGeometry(0.036, 48),
      new THREE.MeshBasicMaterial({ transparent: true, opacity: 0, depthWrite: false, side: THREE.DoubleSide }));
    this.goalDisc.name = 'goal-disc';
    this.goal.add(ring, this.goalGhost, this.goalDisc);
    this.setPart([{ centre: [0, 0, 0], half: [0.025, 0.025, 0.025] }]); // the block, until the hello names the part
    this.goal.visible = false;
    this.root.add(this.goal);

    this.tcp = new THREE.Mesh(new THREE.SphereGeometry(0.009, 20, 14), std(COLORS.tcp, { emissive: 0x0b3a48 }));
    this.tcp.name = 'tcp';
    this.tcp.visible = false;
    this.root.add(this.tcp);

    this.previous = new THREE.Mesh(new THREE.SphereGeometry(0.011, 20, 14),
      std(COLORS.previous, { transparent: true, opacity: 0.75, emissive: 0x3a0f39 }));
    this.previous.name = 'previous-target';
    this.previous.visible = false;
    this.root.add(this.previous);

    this.target = new THREE.Group();
    this.target.name = 'target';
    const ball = new THREE.Mesh(new THREE.SphereGeometry(0.012, 24, 16), std(COLORS.target, { emissive: 0x4a3a00 }));
    this.target.add(ball);
    this.target.visible = false;
    this.root.add(this.target);

    // Depth cues: a drop line from the target to the table and its footprint there; a line from the TCP.
    this.dropLine = new THREE.Line(new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), new THREE.Vector3()]),
      new THREE.LineDashedMaterial({ color: COLORS.target, dashSize: 0.01, gapSize: 0.007, transparent: true, opacity: 0.8 }));
    this.footprint = new THREE.Mesh(new THREE.RingGeometry(0.008, 0.014, 32),
      new THREE.MeshBasicMaterial({ color: COLORS.target, side: THREE.DoubleSide, transparent: true, opacity: 0.7 }));
    this.moveLine = new THREE.Line(new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), new THREE.Vector3()]),
      new THREE.LineDashedMaterial({ color: 0xffffff, dashSize: 0.012, gapSize: 0.01, transparent: true, opacity: 0.45 }));
    for (const o of [this.dropLine, this.footprint, this.moveLine]) {
      o.visible = false;
      this.root.add(o);
    }
  }

  /** Draw the part as its boxes ({centre, half} in its frame, m: the part library's); its outline at the goal. */
  setPart(boxes) {
    this.object.clear();
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (const { centre, half } of boxes) {
      const box = new THREE.Mesh(new THREE.BoxGeometry(2 * half[0], 2 * half[1], 2 * half[2]), this.objectMaterial);
      box.position.copy(v3(centre));
      this.object.add(box);
      for (let i = 0; i < 3; i++) {
        lo[i] = Math.min(lo[i], centre[i] - half[i]);
        hi[i] = Math.max(hi[i], centre[i] + half[i]);
      }
    }
    this.objectHeight = hi[2] - lo[2];
    this.goalGhost.scale.set(hi[0] - lo[0], hi[1] - lo[1], this.objectHeight);
  }

  // -- configuration from the server's hello -----------------------------------------------------
  configure(hello) {
    const robot = hello.robot || {};
    if (robot.workspace) this.workspace = { lo: robot.workspace.lo.slice(), hi: robot.workspace.hi.slice() };
    if (hello.part) this.setPart(hello.part.boxes);
    this.jointNames = robot.joint_names || [];
    const lo = v3(this.workspace.lo);
    const hi = v3(this.workspace.hi);
    const size = hi.clone().sub(lo);
    const mid = lo.clone().add(hi).multiplyScalar(0.5);
    this.workspaceBox.scale.copy(size);
    this.workspaceBox.position.copy(mid);
    this.workspaceFloor.scale.set(size.x, size.y, 1);
    this.workspaceFloor.position.set(mid.x, mid.y, 0.0005);
    if (robot.urdf_url && !this.robotState.loading && !this.robotState.loaded) this.loadRobot(robot.urdf_url);
    this.resetCamera();
    this.requestRender();
  }

  loadRobot(url) {
    this.robotState.loading = true;
    const manager = new THREE.LoadingManager();
    const loader = new URDFLoader(manager);
    // Mesh URIs in the served URDF are absolute paths (/robot/pkg/...); urdf-loader prefixes them with
    // its working path, so make that the origin.
    loader.workingPath = window.location.origin;
    manager.onError = (u) => {
      this.robotState.meshErrors += 1;
      console.warn('robot mesh failed to load:', u);
    };
    let model = null;
    let done = false;
    const finish = () => {
      if (done || !model) return;
      done = true;
      this.robotState.loading = false;
      this.robotState.loaded = true;
      this.requestRender();
      this.dispatchEvent(new Event('robot'));
    };
    manager.onLoad = finish; // after the URDF and every mesh it names (urdf-loader ends the URDF item last)
    loader.load(url, (robot) => {
      model = robot;
      robot.name = 'robot';
      robot.traverse((o) => { if (o.isMesh) o.castShadow = false; });
      this.robot = robot;
      this.root.add(robot);
      if (this.pendingJoints) this.setJoints(this.pendingJoints);
      this.requestRender();
    }, undefined, (err) => {
      this.robotState.loading = false;
      this.robotState.error = String(err && err.message ? err.message : err);
      this.dispatchEvent(new Event('robot'));
    });
  }

  // -- the request -----------------------------------------------------------------------------
  setJoints(q) {
    this.pendingJoints = q;
    if (!this.robot) return;
    this.jointNames.forEach((name, i) => {
      if (this.robot.joints[name] && Number.isFinite(q[i])) this.robot.setJointValue(name, q[i]);
    });
    this.robot.updateMatrixWorld(true);
    this.requestRender();
  }

  /** Joint values the loaded arm shows, by name (rad). */
  jointValues() {
    const out = {};
    if (!this.robot) return out;
    for (const name of this.jointNames) {
      const j = this.robot.joints[name];
      if (j) out[name] = j.angle;
    }
    return out;
  }

  /** The arm model's TCP link (forward kinematics of urdf-loader) in the robot frame, or null. */
  modelTcp() {
    if (!this.robot || !this.robot.links || !this.robot.links.tcp) return null;
    const p = this.robot.links.tcp.getWorldPosition(new THREE.Vector3()); // updates its parent chain
    this.root.worldToLocal(p);
    return [p.x, p.y, p.z];
  }

  showRequest(req) {
    const s = req.state;
    this.setJoints(s.joints);
    this.object.position.copy(v3(s.object.position));
    const q = s.object.orientation; // x, y, z, w
    this.object.quaternion.set(q[0], q[1], q[2], q[3]);
    this.object.visible = true;
    this.goal.position.copy(v3(s.goal));
    this.goalRing.position.set(0, 0, -s.goal[2] + 0.001);
    this.goalDisc.position.set(0, 0, -s.goal[2] + 0.0012);
    this.goal.visible = true;
    this.tcp.position.copy(v3(s.tcp));
    this.tcp.visible = true;
    if (req.remark && req.previous_target) {
      this.previous.position.copy(v3(req.previous_target));
      this.previous.visible = true;
    } else {
      this.previous.visible = false;
    }
    this.target.visible = true;
    this.gizmo.enabled = true;
    this.gizmo.getHelper().visible = !this.renderer.xr.isPresenting;
    this._updateCues();
    this.requestRender();
  }

  clearRequest() {
    this.gizmo.enabled = false;
    this.gizmo.getHelper().visible = false;
    this.requestRender();
  }

  clamp(p) {
    const { lo, hi } = this.workspace;
    return [0, 1, 2].map((i) => Math.min(hi[i], Math.max(lo[i], p[i])));
  }

  /** Put the target at p (robot frame), clamped into the workspace box and rounded; returns it. */
  setTarget(p) {
    const t = roundTarget(this.clamp(p)).map((v, i) => Math.min(this.workspace.hi[i], Math.max(this.workspace.lo[i], v)));
    this.target.position.set(t[0], t[1], t[2]);
    this._updateCues();
    this.requestRender();
    return t;
  }

  getTarget() {
    const p = this.target.position;
    return [p.x, p.y, p.z];
  }

  _targetMoved(final) {
    const p = this.getTarget();
    const c = this.clamp(p);
    if (c.some((v, i) => v !== p[i])) this.target.position.set(c[0], c[1], c[2]);
    if (final) this.setTarget(this.getTarget());
    this._updateCues();
    this.dispatchEvent(new CustomEvent('target', { detail: { final } }));
    this.requestRender();
  }

  _updateCues() {
    const t = this.target.position;
    const show = this.target.visible;
    const drop = this.dropLine.geometry.attributes.position;
    drop.setXYZ(0, t.x, t.y, t.z);
    drop.setXYZ(1, t.x, t.y, 0.001);
    drop.needsUpdate = true;
    this.dropLine.computeLineDistances();
    this.footprint.position.set(t.x, t.y, 0.0015);
    const mv = this.moveLine.geometry.attributes.position;
    const c = this.tcp.position;
    mv.setXYZ(0, c.x, c.y, c.z);
    mv.setXYZ(1, t.x, t.y, t.z);
    mv.needsUpdate = true;
    this.moveLine.computeLineDistances();
    for (const o of [this.dropLine, this.footprint]) o.visible = show;
    this.moveLine.visible = show && this.tcp.visible;
    for (const g of [this.dropLine.geometry, this.moveLine.geometry]) g.computeBoundingSphere();
  }

  /**
   * Click to place: what the pixel (page coordinates) shows, and the target it stands for in `phase`
   * (see `pickRay`). Null off those surfaces.
   */
  pick(clientX, clientY, phase, task = {}, here = false) {
    const rect = this.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2((clientX - rect.left) / rect.width * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    const ray = new THREE.Raycaster();
    this.scene.updateMatrixWorld(true);
    ray.setFromCamera(ndc, this.camera);
    return this.pickRay(ray, phase, task, here);
  }

  /**
   * What a ray (world frame: the desktop camera's, or a headset controller's) meets first, and the target it
   * stands for in `phase`. On the object, its centre; on the goal, the goal; on the table, that point; each
   * at the phase's height (task parameters from the hello): the approach hovers approach_height above the
   * part's top, the grasp and the release are at the top of a part on the table, lift and transport at
   * lift_height. With `here` ("exactly here": the person teaches the point), a hit on the object stands for the
   * point hit on its surface, at that face's height, not for its centre. Null off those surfaces.
   */
  pickRay(ray, phase, task = {}, here = false) {
    this.scene.updateMatrixWorld(true);
    const surfaces = [this.object, this.goalDisc, this.tableGroup[0]].filter((o) => o.visible || o === this.goalDisc);
    const hit = ray.intersectObjects(surfaces, true)[0];
    if (!hit) return null;
    const top = this.objectHeight; // a part standing on the table (z = 0)
    const z = phase === 0 ? top + (task.approach_height ?? 0.08)
      : phase === 2 || phase === 3 ? (task.lift_height ?? 0.15) : top;
    if (hit.object.parent === this.object && here) {
      const p = this.root.worldToLocal(hit.point.clone()); // the face hit, as the part is drawn (where the cell sees it)
      const zHere = phase === 0 ? p.z + (task.approach_height ?? 0.08) : phase === 2 || phase === 3 ? z : p.z;
      return { on: 'object', point: [p.x, p.y, zHere] };
    }
    if (hit.object.parent === this.object) return { on: 'object', point: [this.object.position.x, this.object.position.y, z] };
    if (hit.object === this.goalDisc) return { on: 'goal', point: [this.goal.position.x, this.goal.position.y, z] };
    const p = this.root.worldToLocal(hit.point.clone());
    return { on: 'table', point: [p.x, p.y, z] };
  }

  // -- camera, rendering, screen positions -----------------------------------------------------
  resetCamera() {
    const { lo, hi } = this.workspace;
    const mid = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 3];
    const eye = [mid[0] + 1.1, mid[1] - 0.62, 0.92];
    this.camera.position.copy(this.toWorld(eye));
    this.orbit.target.copy(this.toWorld([mid[0] - 0.12, mid[1] - 0.05, mid[2] + 0.06]));
    this.orbit.update();
    this.requestRender();
  }

  toWorld(p) {
    this.root.updateMatrixWorld(true);
    return this.root.localToWorld(v3(p));
  }

  resize() {
    const w = Math.max(1, this.container.clientWidth);
    const h = Math.max(1, this.container.clientHeight);
    if (this.renderer.xr.isPresenting) return;
    this.renderer.setSize(w, h, true);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  requestRender() {
    if (this._scheduled || this.renderer.xr.isPresenting) return;
    this._scheduled = true;
    requestAnimationFrame(() => {
      this._scheduled = false;
      if (!this.renderer.xr.isPresenting) this.render();
    });
  }

  render() {
    this.renderer.render(this.scene, this.camera);
    this.frames += 1;
  }

  /** Page coordinates (CSS px) of a robot-frame point, as the desktop camera shows it. */
  screenOf(p) {
    return this._screenOfWorld(this.toWorld(p));
  }

  _screenOfWorld(w) {
    this.camera.updateMatrixWorld(true);
    const n = w.clone().project(this.camera);
    const r = this.renderer.domElement.getBoundingClientRect();
    return { x: r.left + (n.x + 1) / 2 * r.width, y: r.top + (1 - n.y) / 2 * r.height, visible: Math.abs(n.z) <= 1 };
  }

  /**
   * Page coordinates of a point on the gizmo's translate handle for `axis` ('X', 'Y', 'Z': the robot
   * frame's axes), found by asking the gizmo's own picker which handle is under each candidate pixel.
   */
  gizmoHandle(axis = 'X') {
    const gizmo = this.gizmo;
    this.scene.updateMatrixWorld(true);
    gizmo.getHelper().updateMatrixWorld(true);
    const origin = this.target.getWorldPosition(new THREE.Vector3());
    const dir = new THREE.Vector3(axis === 'X' ? 1 : 0, axis === 'Y' ? 1 : 0, axis === 'Z' ? 1 : 0)
      .applyQuaternion(this.target.getWorldQuaternion(new THREE.Quaternion()));
    const factor = origin.distanceTo(this.camera.position) *
      Math.min(1.9 * Math.tan(Math.PI * this.camera.fov / 360) / this.camera.zoom, 7) * gizmo.size / 4;
    const picker = gizmo._gizmo.picker.translate;
    const ray = new THREE.Raycaster();
    const rect = this.renderer.domElement.getBoundingClientRect();
    for (const s of [0.45, 0.35, 0.55, 0.25, 0.65, -0.45, -0.35]) {
      const w = origin.clone().addScaledVector(dir, s * factor);
      const px = this._screenOfWorld(w);
      const ndc = new THREE.Vector2((px.x - rect.left) / rect.width * 2 - 1, -((px.y - rect.top) / rect.height) * 2 + 1);
      ray.setFromCamera(ndc, this.camera);
      const hits = ray.intersectObjects(picker.children, true);
      if (hits.length && hits[0].object.name === axis) return { x: px.x, y: px.y, axis };
    }
    return null;
  }

  /**
   * For the arrow keys: the robot axis (index, sign) closest to the view's "right" and "away"
   * directions projected on the table, so the arrows move the target the way the screen suggests.
   */
  viewAxes() {
    const cam = this.camera.getWorldDirection(new THREE.Vector3());
    const m = new THREE.Matrix4().copy(this.root.matrixWorld).invert();
    const fwd = cam.clone().transformDirection(m); // robot frame
    fwd.z = 0;
    if (fwd.lengthSq() < 1e-9) fwd.set(-1, 0, 0);
    fwd.normalize();
    const right = new THREE.Vector3(fwd.y, -fwd.x, 0); // fwd x up
    const pick = (v) => (Math.abs(v.x) >= Math.abs(v.y) ? [0, Math.sign(v.x)] : [1, Math.sign(v.y)]);
    return { right: pick(right), away: pick(fwd) };
  }
}
