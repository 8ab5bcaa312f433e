// The page's WebSocket to the annotation server (protocol v1, docs/annotation-protocol.md), with
// automatic reconnect: 0.5 s, 1 s, 2 s, ... up to 8 s between tries, reset once connected. The server
// sends `hello` (with the outstanding request) on every connection, so nothing is lost by reconnecting.

const MIN_DELAY_MS = 500;
const MAX_DELAY_MS = 8000;

export class Connection extends EventTarget {
  /** @param url ws(s)://host/ws?token=...  @param hello () => the client's hello message */
  constructor(url, hello) {
    super();
    this.url = url;
    this.hello = hello;
    this.ws = null;
    this.connected = false;
    this.everConnected = false;
    this.failures = 0; // consecutive tries that did not open
    this.reconnects = 0;
    this.retryAt = null;
    this._timer = null;
    this._closed = false;
  }

  start() {
    this._connect();
  }

  _connect() {
    this._timer = null;
    this.retryAt = null;
    let opened = false;
    const ws = new WebSocket(this.url);
    this.ws = ws;
    this._emit('state');
    ws.onopen = () => {
      opened = true;
      this.connected = true;
      if (this.everConnected) this.reconnects += 1;
      this.everConnected = true;
      this.failures = 0;
      ws.send(JSON.stringify(this.hello()));
      this._emit('state');
    };
    ws.onmessage = (e) => {
      let msg;
      try { msg = JSON.parse(e.data); } catch { return; }
      this.dispatchEvent(new CustomEvent('message', { detail: msg }));
    };
    ws.onclose = (e) => {
      if (this.ws !== ws) return;
      this.connected = false;
      this.lastClose = { code: e.code, reason: e.reason, opened };
      if (!opened) this.failures += 1;
      if (!this._closed) {
        const delay = Math.min(MAX_DELAY_MS, MIN_DELAY_MS * 2 ** Math.min(this.failures, 5));
        this.retryAt = Date.now() + delay;
        this._timer = setTimeout(() => this._connect(), delay);
      }
      this._emit('state');
    };
  }

  /** Send a message now; false when not connected (the caller says so to the person). */
  send(msg) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return false;
    this.ws.send(JSON.stringify(msg));
    return true;
  }

  /** Drop the current socket (as a network failure would); the reconnect logic takes over. */
  drop() {
    if (this.ws) this.ws.close(4000, 'dropped by the page');
  }

  close() {
    this._closed = true;
    if (this._timer) clearTimeout(this._timer);
    if (this.ws) this.ws.close(1000, 'page closed');
  }

  _emit(kind) {
    this.dispatchEvent(new Event(kind));
  }
}
