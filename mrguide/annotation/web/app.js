// The annotation page: shows what the trainer asks, lets a person mark the waypoint, sends the answer.
//
// Protocol: docs/annotation-protocol.md (v1). The token comes from this page's own URL (?token=...)
// and is passed on to the WebSocket. Query parameters:
//   token=...   required (the server refuses the page and the socket without it)
//   xr=PROFILE  emulate a headset with Meta's IWER before WebXR is set up (quest3, quest3-vr,
//               hololens2; see emulation.js). For tests and demos; a real headset needs none.
//
// Test hook (used by mrguide/annotation/headless.py and the browser tests; harmless for a person):
//   window.mrguide.ready                 true once the page has wired itself up
//   window.mrguide.state()               {connected, clientId, requestId, phase, prompt, target, vacuum,
//                                         lastAck, claimedBy, closed, status, robot, frames, xr, ...}
//   window.mrguide.setTarget([x,y,z])    move the target (robot frame, m; clamped, rounded to 0.1 mm)
//   window.mrguide.setVacuum(bool)       set the vacuum command
//   window.mrguide.setHere(bool)         "exactly here": the answer teaches the point (protocol `here`)
//   window.mrguide.submit() / skip()     as the buttons (false when there is nothing to answer)
//   window.mrguide.intervene()           as the Intervene button (false while a request is shown)
//   window.mrguide.gizmoHandle(axis)     page coordinates {x, y} of the gizmo's X/Y/Z arrow, for a mouse drag
//   window.mrguide.screenOf([x,y,z])     page coordinates of a robot-frame point (clicked, it places the target)
//   window.mrguide.enterXR() / exitXR()  as the headset button
//   window.mrguide.dropConnection()      close the socket as a network failure would (reconnects)
//   window.mrguide.redraw()              draw the view again (it draws on demand)
//   window.mrguide.shown()               {phase_index, object, goal, object_height} of the outstanding request
//   window.mrguide.part()                {boxes (each one's x size, m), height} of the part as drawn
//   window.mrguide.autoSubmit(on)        answer every new request as soon as it is shown, with the start
//                                        target and the suggested vacuum (benchmarks: no polling delay)
//   window.mrguide.xrDevice              IWER's XRDevice when ?xr= is given (tests drive it)

import { TwinView, roundTarget } from './scene.js';
import { Connection } from './connection.js';
import { XRView } from './xr.js';

const params = new URLSearchParams(window.location.search);
const token = params.get('token') || '';
const xrProfile = params.get('xr');

const $ = (id) => document.getElementById(id);
const NUDGE_M = 0.005;
const FINE_NUDGE_M = 0.001;
const CANCEL_TEXT = {
  answered: 'answered by another client',
  timeout: 'timed out: the trainer went on without it',
  skipped: 'skipped',
  interrupted: 'training stopped',
  shutdown: 'the server is shutting down',
};

const S = {
  clientId: null,
  hello: null,
  request: null, // the outstanding request message
  receivedAt: 0,
  start: null, // where the target started for this request
  target: null,
  vacuum: false,
  here: false, // the answer teaches its point: "not there — here"
  claimedBy: null,
  claimSent: false,
  submitted: null, // {id, target, vacuum}
  lastAck: null,
  refusals: [],
  closed: null, // {id, reason} of the last request that closed
  status: {},
  answers: 0,
  autoSubmit: false,
  placedOn: null, // what the last click placed the target on: 'object', 'goal' or 'table'
  intervened: false, // an intervene was sent since the last request
};

async function main() {
  let xrDevice = null;
  if (xrProfile) {
    const { installEmulatedXR } = await import('./emulation.js');
    xrDevice = installEmulatedXR(xrProfile);
    const badge = $('emulated');
    badge.textContent = `WebXR emulated: ${xrDevice.name} (IWER)`;
    badge.hidden = false;
  }

  const view = new TwinView($('viewport'));
  const xr = new XRView(view, {
    onSelectPoint: (p, on) => { S.placedOn = on; setTarget(p, true); submit('headset'); },
    pickRay: (ray) => (S.request ? view.pickRay(ray, S.request.phase_index, (S.hello && S.hello.task) || {}, S.here) : null),
    onSqueeze: () => (S.request ? setVacuum(!S.vacuum, true) : intervene()),
    onPresenting: (on) => {
      conn.send(helloMessage());
      $('xr-button').textContent = on ? 'Exit headset' : xrButtonLabel();
      render();
    },
    label: () => [
      S.request ? `${phaseLabel(S.request)} · vacuum ${S.vacuum ? 'ON' : 'OFF'} (squeeze)` : 'No request · squeeze to step in',
      S.request ? S.request.prompt : (S.closed ? `Request closed: ${CANCEL_TEXT[S.closed.reason] || S.closed.reason}` : 'Waiting for the trainer to ask.'),
      `${feedbackText()}   step ${S.status.step ?? '–'}`,
    ],
  });
  const helloMessage = () => ({ type: 'hello', protocol: 1, client: xr.info.presenting ? 'headset' : 'browser',
    name: xrDevice ? `emulated ${xrDevice.name}` : navigator.userAgent.slice(0, 80) });

  const wsUrl = `${window.location.protocol === 'https:' ? 'wss' : 'ws'}://${window.location.host}/ws?token=${encodeURIComponent(token)}`;
  const conn = new Connection(wsUrl, helloMessage);

  // -- messages from the server -----------------------------------------------------------------
  conn.addEventListener('message', (e) => {
    const m = e.detail;
    switch (m.type) {
      case 'hello': onHello(m); break;
      case 'request': showRequest(m); break;
      case 'claimed':
        if (S.request && m.id === S.request.id) S.claimedBy = m.client_id;
        break;
      case 'ack': onAck(m); break;
      case 'cancel': onCancel(m); break;
      case 'status': S.status = { ...S.status, ...m }; break;
      default: break;
    }
    render();
  });
  conn.addEventListener('state', render);

  function onHello(m) {
    S.clientId = m.client_id;
    const first = !S.hello;
    S.hello = m;
    if (first) view.configure(m);
    xr.setRegistration(m.registration);
    if (m.status) S.status = { ...S.status, ...m.status };
    if (m.request) showRequest(m.request);
    else if (S.request) closeRequest({ id: S.request.id, reason: 'closed while this page was disconnected' });
  }

  function showRequest(req) {
    const same = S.request && S.request.id === req.id;
    S.request = req;
    S.claimedBy = req.claimed_by;
    if (!same) {
      S.placedOn = null;
      S.intervened = false;
      S.receivedAt = performance.now();
      S.claimSent = false;
      S.submitted = null;
      S.closed = null;
      S.vacuum = !!req.suggested_vacuum;
      S.here = false;
      const start = req.remark && req.previous_target ? req.previous_target : req.state.tcp;
      view.showRequest(req);
      S.start = view.setTarget(start);
      S.target = S.start;
      if (S.autoSubmit) submit();
    } else {
      // Reconnected mid-request: keep what the person has marked so far.
      view.showRequest(req);
      S.target = view.setTarget(S.target);
    }
  }

  function onAck(m) {
    S.lastAck = m;
    if (!m.accepted) {
      S.refusals.push({ for: m.for, id: m.id, reason: m.reason });
      if (S.submitted && m.for === 'answer' && m.id === S.submitted.id) S.submitted = null;
    } else if (m.for === 'answer') {
      S.answers += 1;
    }
  }

  function onCancel(m) {
    if (S.request && m.id === S.request.id) closeRequest(m);
  }

  function closeRequest(m) {
    S.closed = { id: m.id, reason: m.reason, mine: !!(S.submitted && S.submitted.id === m.id && m.reason === 'answered') };
    S.request = null;
    S.claimedBy = null;
    view.clearRequest();
  }

  // -- what the person does -----------------------------------------------------------------------
  const canAnswer = () => !!S.request && conn.connected && !(S.claimedBy && S.claimedBy !== S.clientId) &&
    !(S.submitted && S.submitted.id === S.request.id);

  function claim() {
    if (S.request && !S.claimSent && !S.claimedBy) {
      S.claimSent = conn.send({ type: 'claim', id: S.request.id });
    }
  }

  function setTarget(p, fromXR = false) {
    if (!S.request || !Array.isArray(p) || p.length !== 3 || !p.every(Number.isFinite)) return null;
    if (!fromXR) claim();
    S.target = view.setTarget(p);
    render();
    return S.target;
  }

  function setVacuum(on, fromXR = false) {
    if (!S.request) return S.vacuum;
    if (!fromXR) claim();
    S.vacuum = !!on;
    render();
    return S.vacuum;
  }

  function setHere(on) {
    if (!S.request) return S.here;
    claim();
    S.here = !!on;
    render();
    return S.here;
  }

  function submit() {
    if (!canAnswer()) {
      render();
      return false;
    }
    const msg = { type: 'answer', id: S.request.id, target: S.target.slice(), vacuum: S.vacuum };
    if (S.here) msg.here = true; // "not there — here": the point is taught, not read as the part's centre
    if (!conn.send(msg)) return false;
    S.submitted = { id: msg.id, target: msg.target, vacuum: msg.vacuum };
    render();
    return true;
  }

  function skip() {
    if (!canAnswer()) return false;
    return conn.send({ type: 'skip', id: S.request.id });
  }

  // Step in at any time: the trainer cuts the agent's running episode and asks for its demonstration.
  const canIntervene = () => conn.connected && !S.request;
  function intervene() {
    if (!canIntervene()) return false;
    S.intervened = conn.send({ type: 'intervene' });
    render();
    return S.intervened;
  }

  function nudge(axis, delta) {
    if (!S.request) return;
    const p = S.target.slice();
    p[axis] += delta;
    setTarget(p);
  }

  // Click (or tap) to place: a press and release on the same spot of the view puts the target on what it
  // shows (scene.js `pick`), also through the gizmo (whose arrows stand over the goal when the arm holds the
  // part above it); a drag still orbits or moves an arrow, and the keys still adjust.
  const canvas = view.renderer.domElement;
  let press = null;
  canvas.addEventListener('pointerdown', (e) => {
    press = e.isPrimary ? { x: e.clientX, y: e.clientY } : null;
  });
  canvas.addEventListener('pointerup', (e) => {
    if (!press || !S.request || Math.hypot(e.clientX - press.x, e.clientY - press.y) > 5) return;
    press = null;
    const picked = view.pick(e.clientX, e.clientY, S.request.phase_index, (S.hello && S.hello.task) || {}, S.here);
    if (picked) {
      S.placedOn = picked.on;
      setTarget(picked.point);
    }
  });

  view.addEventListener('interact', claim);
  view.addEventListener('target', (e) => {
    if (!S.request) return;
    if (e.detail.final) S.target = view.getTarget();
    else S.target = roundTarget(view.getTarget());
    render();
  });
  view.addEventListener('robot', render);

  $('submit').addEventListener('click', () => submit());
  $('skip').addEventListener('click', () => skip());
  $('intervene').addEventListener('click', () => intervene());
  $('vacuum').addEventListener('click', () => setVacuum(!S.vacuum));
  $('here').addEventListener('click', () => setHere(!S.here));
  document.addEventListener('keydown', (e) => {
    if (e.target && ['INPUT', 'TEXTAREA', 'SELECT'].includes(e.target.tagName)) return;
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    const step = e.shiftKey ? FINE_NUDGE_M : NUDGE_M;
    const axes = view.viewAxes();
    let handled = true;
    switch (e.key) {
      case 'Enter': submit(); break;
      case 's': case 'S': skip(); break;
      case 'i': case 'I': intervene(); break;
      case 'v': case 'V': setVacuum(!S.vacuum); break;
      case 'h': case 'H': setHere(!S.here); break;
      case 'c': case 'C': view.resetCamera(); break;
      case 'Home': if (S.start) setTarget(S.start); break;
      case 'ArrowRight': nudge(axes.right[0], axes.right[1] * step); break;
      case 'ArrowLeft': nudge(axes.right[0], -axes.right[1] * step); break;
      case 'ArrowUp': nudge(axes.away[0], axes.away[1] * step); break;
      case 'ArrowDown': nudge(axes.away[0], -axes.away[1] * step); break;
      case 'PageUp': nudge(2, step); break;
      case 'PageDown': nudge(2, -step); break;
      default: handled = false;
    }
    if (handled) e.preventDefault();
  });

  const xrButtonLabel = () => (xr.info.arSupported ? 'Enter AR' : xr.info.vrSupported ? 'Enter VR (no AR here)' : 'Enter AR');
  $('xr-button').addEventListener('click', async () => {
    try {
      if (xr.info.presenting) await xr.exit();
      else await xr.enter();
    } catch (err) {
      xr.info.error = String(err && err.message ? err.message : err);
    }
    render();
  });

  // -- drawing the panel --------------------------------------------------------------------------
  function phaseLabel(req) {
    return `Phase ${req.phase_index + 1}/5 · ${req.phase}`;
  }

  function feedbackText() {
    if (S.request && S.claimedBy && S.claimedBy !== S.clientId) return `Claimed by ${S.claimedBy}: another person is answering.`;
    const a = S.lastAck;
    if (a && !a.accepted) return `Refused: ${a.reason}`;
    if (S.submitted && S.request && S.submitted.id === S.request.id) return 'Sent; waiting for the server…';
    if (S.closed && S.closed.mine) return 'Your answer was accepted.';
    if (a && a.accepted && a.for === 'answer') return 'Your answer was accepted.';
    if (S.intervened && !S.request) return 'Stepping in: the trainer will ask for this episode\'s demonstration.';
    return '';
  }

  const mm = (v) => (v * 1000).toFixed(1);
  function render() {
    const st = conn.connected ? 'connected' : conn.everConnected ? 'reconnecting' : 'connecting';
    const conEl = $('conn');
    conEl.className = `pill ${conn.connected ? 'ok' : 'bad'}`;
    let text = conn.connected ? `connected · ${S.clientId || ''}` : st;
    if (!conn.connected && conn.retryAt) text += ` in ${Math.max(0, Math.ceil((conn.retryAt - Date.now()) / 1000))} s`;
    if (!conn.connected && conn.failures >= 3) text += ' · is training running, is the token right?';
    conEl.textContent = text;
    conEl.dataset.state = st;

    const req = S.request;
    const phase = $('phase');
    phase.textContent = req ? phaseLabel(req) : 'no request';
    phase.className = `phase ${req ? `p${req.phase_index}` : 'idle'}`;
    $('prompt').textContent = req ? req.prompt
      : S.closed ? `Request closed: ${CANCEL_TEXT[S.closed.reason] || S.closed.reason}. Waiting for the next one.`
        : 'Waiting for the trainer to ask for a waypoint.';
    $('prompt').classList.toggle('remark', !!(req && req.remark));
    const claimEl = $('claim');
    if (req && S.claimedBy && S.claimedBy !== S.clientId) {
      claimEl.hidden = false;
      claimEl.textContent = `Claimed by ${S.claimedBy}: another person is answering this request.`;
      claimEl.className = 'note warn';
    } else if (req && S.claimedBy === S.clientId) {
      claimEl.hidden = false;
      claimEl.textContent = 'You are answering this request.';
      claimEl.className = 'note';
    } else {
      claimEl.hidden = true;
    }

    const t = S.target;
    $('tx').textContent = t && req ? mm(t[0]) : '–';
    $('ty').textContent = t && req ? mm(t[1]) : '–';
    $('tz').textContent = t && req ? mm(t[2]) : '–';
    const ws = view.workspace;
    $('bounds').textContent = `box x ${mm(ws.lo[0])}…${mm(ws.hi[0])}, y ${mm(ws.lo[1])}…${mm(ws.hi[1])}, z ${mm(ws.lo[2])}…${mm(ws.hi[2])}`;
    const vac = $('vacuum');
    vac.disabled = !req;
    vac.setAttribute('aria-pressed', String(S.vacuum));
    vac.classList.toggle('on', S.vacuum);
    vac.innerHTML = `Vacuum <b>${S.vacuum ? 'ON' : 'OFF'}</b> <kbd>V</kbd>`;
    const here = $('here');
    here.disabled = !req;
    here.setAttribute('aria-pressed', String(S.here));
    here.classList.toggle('on', S.here);
    $('submit').disabled = !canAnswer();
    $('skip').disabled = !canAnswer();
    $('intervene').disabled = !canIntervene();
    const fb = $('feedback');
    fb.textContent = feedbackText();
    fb.className = `feedback ${S.lastAck && !S.lastAck.accepted ? 'bad' : 'ok'}`;

    const s = S.status;
    const fmt = (v, d = 0) => (v === undefined || v === null ? '–' : typeof v === 'number' ? v.toFixed(d) : String(v));
    $('st-step').textContent = s.step === undefined ? '–' : `${s.step}${s.total_steps ? ` / ${s.total_steps}` : ''}`;
    $('st-cycle').textContent = s.cycle === undefined ? '–' : `${s.cycle} · v${fmt(s.version)}`;
    $('st-episode').textContent = fmt(s.episode);
    $('st-lambda').textContent = fmt(s.lambda, 3);
    $('st-success').textContent = s.success_rate === undefined ? '–' : `${(100 * s.success_rate).toFixed(0)} %`;
    $('st-asked').textContent = `${fmt(s.asked)} / ${fmt(s.reused)}`;
    $('st-remarks').textContent = fmt(s.remarks);
    $('st-interventions').textContent = s.interventions === undefined ? '–' : `${s.interventions} (${fmt(s.person_interventions)})`;
    $('st-skipped').textContent = `${fmt(s.skipped)} / ${fmt(s.fallbacks)}`;
    $('st-robot').textContent = s.robot_s === undefined ? '–' : `${(s.robot_s / 60).toFixed(1)} min, ${fmt(s.resets)} resets, ${fmt(s.probes)} probes`;
    $('st-grasp').textContent = s.grasp === undefined ? '–' : s.grasp === null ? 'middle of the top (centre prior)'
      : `x ${(1000 * s.grasp[0]).toFixed(0)}, y ${(1000 * s.grasp[1]).toFixed(0)} mm from the part's centre · ${fmt(s.corrections)} corrections`;
    $('st-waiting').textContent = s.waiting ? 'yes — for an annotation' : s.waiting === false ? 'no' : '–';
    $('st-clients').textContent = fmt(s.clients);
    const refused = s.refused ? Object.values(s.refused).reduce((a, b) => a + b, 0) : undefined;
    $('st-refused').textContent = fmt(refused);
    $('waiting').hidden = !(s.waiting && req);

    const banner = $('banner');
    if (view.robotState.error) {
      banner.hidden = false;
      banner.textContent = `The robot model did not load: ${view.robotState.error}`;
    } else if (!conn.connected && conn.everConnected) {
      banner.hidden = false;
      banner.textContent = 'Connection lost: reconnecting… your mark is kept.';
    } else {
      banner.hidden = true;
    }

    const xb = $('xr-button');
    xb.disabled = !xr.info.available;
    if (!xr.info.presenting) xb.textContent = xrButtonLabel();
    const xrMsg = xr.info.presenting
      ? `${xr.info.mode} · blend ${xr.info.blendMode} · ${xr.info.placed ? `placed by ${xr.info.placementSource}` : 'select to place the robot base on the table'}`
      : xr.info.message;
    $('xr-message').textContent = xr.info.error ? `${xrMsg} — ${xr.info.error}` : xrMsg;
  }

  // Countdown of requests with a deadline, the reconnect timer, and a ping every 10 s while this page holds a
  // claim (the server releases a claim whose client sends nothing for its claim timeout).
  let lastPing = 0;
  setInterval(() => {
    if (S.request && S.claimedBy === S.clientId && conn.connected && performance.now() - lastPing > 10000) {
      conn.send({ type: 'ping' });
      lastPing = performance.now();
    }
    const req = S.request;
    const left = req ? (req.remaining_s ?? req.timeout_s) : null; // remaining_s: sent with hello on (re)connect
    $('countdown').textContent = left
      ? `closes in ${Math.max(0, Math.ceil(left - (performance.now() - S.receivedAt) / 1000))} s` : '';
    if (!conn.connected) render();
  }, 500);

  window.mrguide = {
    ready: false,
    xrDevice,
    state: () => ({
      connected: conn.connected,
      reconnects: conn.reconnects,
      clientId: S.clientId,
      requestId: S.request ? S.request.id : null,
      phase: S.request ? S.request.phase : null,
      prompt: S.request ? S.request.prompt : null,
      target: S.request ? S.target.slice() : null,
      vacuum: S.vacuum,
      here: S.here,
      claimedBy: S.claimedBy,
      submitted: S.submitted,
      lastAck: S.lastAck,
      refusals: S.refusals.slice(),
      closed: S.closed,
      answers: S.answers,
      placedOn: S.placedOn,
      status: { ...S.status },
      workspace: view.workspace,
      robot: { ...view.robotState, joints: view.jointValues(), tcp: view.modelTcp() },
      frames: view.frames,
      xr: { ...xr.info, placement: view.root.matrix.toArray() }, // robot frame -> three world, column-major
    }),
    setTarget: (p) => setTarget(p),
    setVacuum: (on) => setVacuum(on),
    setHere: (on) => setHere(on),
    submit: () => submit(),
    skip: () => skip(),
    intervene: () => intervene(),
    // what the outstanding request shows: the part, the goal, the phase (for a scripted person)
    shown: () => (S.request ? { phase_index: S.request.phase_index, object: S.request.state.object.position,
      goal: S.request.state.goal, object_height: view.objectHeight } : null),
    // the part as drawn: its boxes' sizes (m) and its height
    part: () => ({ boxes: view.object.children.map((b) => b.geometry.parameters.width), height: view.objectHeight }),
    gizmoHandle: (axis) => view.gizmoHandle(axis),
    screenOf: (p) => view.screenOf(p),
    viewAxes: () => view.viewAxes(),
    enterXR: async () => { await xr.enter(); render(); return { ...xr.info }; },
    exitXR: async () => { await xr.exit(); },
    dropConnection: () => conn.drop(),
    redraw: () => view.requestRender(),
    autoSubmit: (on) => { S.autoSubmit = !!on; if (on && S.request) submit(); return S.autoSubmit; },
  };

  await xr.detect();
  render();
  conn.start();
  window.mrguide.ready = true;
}

main().catch((err) => {
  console.error(err);
  const b = document.getElementById('banner');
  if (b) {
    b.hidden = false;
    b.textContent = `The page failed to start: ${err && err.message ? err.message : err}`;
  }
  window.mrguide = { ready: false, error: String(err && err.message ? err.message : err) };
});
