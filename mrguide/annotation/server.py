"""The annotation web server: the page, its scripts, the robot model and the `/ws` WebSocket.

aiohttp (not `websockets`) because one library serves the static page, the npm modules, the URDF with
its meshes and the WebSocket on one port, with TLS, from one asyncio loop. The loop runs in a daemon
thread; the trainer never waits on it. Bound to 127.0.0.1 unless told otherwise.

What a client sends never reaches a 500: the page and the WebSocket need the access token (403 without),
a browser's `Origin` must be the page's own and the `Host` one this machine answers to (403: no other site,
and no DNS rebinding, can drive a session), paths outside the robot package or of other file types are 404,
idle connections close after KEEPALIVE_S, and a client whose hello speaks another protocol is refused and
disconnected.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import logging
import secrets
import socket
import ssl
import threading
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web

from mrguide.annotation import page_assets
from mrguide.annotation.broker import AnnotationBroker
from mrguide.cell_layout import CUP_RADIUS
from mrguide.config import ConfigError
from mrguide.robot import RobotSpec, urdf_with_tool

log = logging.getLogger(__name__)

WEB_DIR = Path(__file__).with_name("web")
#: File types of the robot package that the page may load (meshes and their textures).
MESH_SUFFIXES = {".dae", ".stl", ".obj", ".png", ".jpg", ".jpeg"}
#: A client that does not read its messages is dropped once this many are queued.
MAX_QUEUED = 1000
#: An HTTP connection that sends no request for this long is closed, s (aiohttp's default: an hour).
KEEPALIVE_S = 15.0
#: The shortest access token `--token` may set (the default is 22 random URL-safe characters).
MIN_TOKEN_LENGTH = 16
#: What /static/ serves from the page's folder: its scripts and style (the page itself only at /, with the token).
STATIC_SUFFIXES = {".js", ".css"}


class ServerError(ConfigError):
    """The server cannot start (port taken, bad certificate, page not installed)."""


class AnnotationServer:
    """Serve `broker` to browsers, headsets and bots; `start()` returns the URL to open."""

    def __init__(
        self,
        broker: AnnotationBroker,
        robot: RobotSpec,
        host: str = "127.0.0.1",
        port: int = 8765,
        cert: str | Path | None = None,
        key: str | Path | None = None,
        token: str | None = None,
        web_dir: Path | None = None,
    ):
        self.broker, self.robot = broker, robot
        self.host, self.port = host, port
        if token is not None and (len(token) < MIN_TOKEN_LENGTH or not token.isascii() or not token.isprintable()):
            raise ServerError(
                f"the access token must be at least {MIN_TOKEN_LENGTH} printable ASCII characters "
                f"(got {len(token)}); leave --token out for a random one"
            )
        self.token = token or secrets.token_urlsafe(16)
        self.web_dir = web_dir or WEB_DIR
        self._ssl = _ssl_context(cert, key)
        self._urdf = urdf_with_tool(robot, "/robot/pkg/", CUP_RADIUS)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._runner: web.AppRunner | None = None
        self._thread: threading.Thread | None = None
        self._sockets: set[web.WebSocketResponse] = set()

    @property
    def scheme(self) -> str:
        return "https" if self._ssl else "http"

    @property
    def url(self) -> str:
        """The page's URL, token included (what a person opens): on a server bound to every interface, with
        this machine's address on the network (a headset cannot reach 127.0.0.1); IPv6 addresses bracketed."""
        host = reachable_address() if self.host in ("0.0.0.0", "::", "") else self.host
        if ":" in host:
            host = f"[{host}]"
        return f"{self.scheme}://{host}:{self.port}/?token={self.token}"

    @property
    def ws_url(self) -> str:
        return self.url.replace("http", "ws", 1).replace("/?token=", "/ws?token=")

    # -- lifecycle ---------------------------------------------------------------------------------
    def start(self, timeout: float = 10.0) -> str:
        """Start the loop thread and bind; returns the URL. Raises ServerError when it cannot serve."""
        if not (self.web_dir / "index.html").is_file():
            raise ServerError(f"the annotation page is not installed: {self.web_dir / 'index.html'} is missing")
        why = page_assets.missing(self.web_dir)
        if why is not None:
            raise ServerError(
                f"{why}: the page's scripts come from npm. In a checkout run `npm ci` in {self.web_dir} "
                "(./run.sh does); an installed mrguide was built without npm: install Node.js and reinstall"
            )
        ready = threading.Event()
        failure: list[BaseException] = []

        def run() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            try:
                loop.run_until_complete(self._bind())
            except BaseException as exc:  # reported to start()'s caller
                failure.append(exc)
                ready.set()
                loop.close()
                return
            ready.set()
            loop.run_forever()
            loop.run_until_complete(self._shutdown())
            loop.close()

        self._thread = threading.Thread(target=run, name="mrguide-annotation-server", daemon=True)
        self._thread.start()
        if not ready.wait(timeout):
            raise ServerError(f"annotation server did not start within {timeout} s")
        if failure:
            exc = failure[0]
            raise ServerError(f"cannot serve on {self.host}:{self.port}: {exc}") from exc
        log.info("annotation server at %s", self.url)
        return self.url

    def stop(self) -> None:
        """Close every connection and the listening socket; idempotent."""
        loop, thread = self._loop, self._thread
        if loop is None or thread is None or not thread.is_alive():
            return
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout=5.0)
        self._thread = None

    async def _bind(self) -> None:
        app = web.Application(middlewares=[_security_headers])
        app.router.add_get("/", self._page)
        app.router.add_get("/ws", self._websocket)
        app.router.add_get("/robot/robot.urdf", self._robot_urdf)
        app.router.add_get("/robot/pkg/{path:.+}", self._robot_file)
        app.router.add_get("/static/{name}", self._static_file)
        modules = self.web_dir / "node_modules"
        if modules.is_dir():
            app.router.add_static("/node_modules/", modules, follow_symlinks=False)
        self._runner = web.AppRunner(app, access_log=None, shutdown_timeout=1.0, keepalive_timeout=KEEPALIVE_S)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port, ssl_context=self._ssl)
        await site.start()
        server = getattr(site, "_server", None)
        if self.port == 0 and server is not None and server.sockets:
            self.port = server.sockets[0].getsockname()[1]

    async def _shutdown(self) -> None:
        for ws in list(self._sockets):
            await ws.close(code=1001, message=b"server shutting down")
        if self._runner is not None:
            await self._runner.cleanup()

    # -- handlers ----------------------------------------------------------------------------------
    def _authorized(self, request: web.Request) -> bool:
        """The token (compared as bytes: any text a client sends is comparable) and, for a browser, the origin."""
        given = request.query.get("token", "").encode("utf-8", "surrogatepass")
        return hmac.compare_digest(given, self.token.encode()) and self._same_origin(request)

    def _same_origin(self, request: web.Request) -> bool:
        """The Host is one this machine answers to (an IP address, localhost or its own name: not a domain an
        attacker points at it), and a browser's Origin, when sent, is the page's own (scheme, host, port)."""
        host = request.host
        try:
            name = urlsplit(f"//{host}").hostname or ""
        except ValueError:  # an unbalanced bracket, a port that is no number
            return False
        if not _local_name(name):
            return False
        origin = request.headers.get("Origin")
        return origin is None or origin == f"{self.scheme}://{host}"

    async def _page(self, request: web.Request) -> web.StreamResponse:
        if not self._authorized(request):
            raise web.HTTPForbidden(
                text="access token missing or wrong, or another site's page: open the URL that mrguide printed\n"
            )
        return web.FileResponse(self.web_dir / "index.html", headers={"Cache-Control": "no-store"})

    async def _static_file(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        path = self.web_dir / name
        if "/" in name or "\x00" in name or path.suffix not in STATIC_SUFFIXES or not path.is_file():
            raise web.HTTPNotFound()
        return web.FileResponse(path)

    async def _robot_urdf(self, request: web.Request) -> web.Response:
        return web.Response(text=self._urdf, content_type="application/xml")

    async def _robot_file(self, request: web.Request) -> web.StreamResponse:
        root = self.robot.package_dir.resolve()
        try:
            path = (root / request.match_info["path"]).resolve()
            found = path.is_relative_to(root) and path.suffix.lower() in MESH_SUFFIXES and path.is_file()
        except (ValueError, OSError):  # a NUL byte, a name too long for the file system
            found = False
        if not found:
            raise web.HTTPNotFound()
        return web.FileResponse(path)

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        if not self._authorized(request):
            raise web.HTTPForbidden(text="access token missing or wrong, or another site's page\n")
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=1 << 20)
        await ws.prepare(request)
        self._sockets.add(ws)
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[dict[str, Any] | None] = asyncio.Queue()

        def send(msg: dict[str, Any]) -> None:
            loop.call_soon_threadsafe(_put, queue, msg)

        writer = asyncio.create_task(_write(ws, queue))
        client_id = self.broker.attach(send)
        try:
            async for msg in ws:
                if msg.type in (WSMsgType.TEXT, WSMsgType.BINARY):
                    if not self.broker.receive(client_id, msg.data):
                        await asyncio.sleep(0.05)  # let the refusal's ack go out first
                        await ws.close(code=1002, message=b"protocol version not supported")
                        break
                elif msg.type is WSMsgType.ERROR:
                    log.info("annotation client %s: connection error %s", client_id, ws.exception())
        finally:
            self.broker.detach(client_id)
            self._sockets.discard(ws)
            queue.put_nowait(None)
            await writer
        return ws


def _put(queue: asyncio.Queue, msg: dict[str, Any]) -> None:
    if queue.qsize() < MAX_QUEUED:
        queue.put_nowait(msg)
    else:  # the client stopped reading: close it rather than grow without bound
        queue.put_nowait(None)


async def _write(ws: web.WebSocketResponse, queue: asyncio.Queue) -> None:
    while True:
        msg = await queue.get()
        if msg is None:
            if not ws.closed:
                await ws.close(code=1008, message=b"too many unread messages")
            return
        if ws.closed:
            return
        try:
            await ws.send_str(json.dumps(msg))
        except (ConnectionError, RuntimeError):
            return


@web.middleware
async def _security_headers(request: web.Request, handler) -> web.StreamResponse:
    response = await handler(request)
    response.headers.setdefault("X-Content-Type-Options", "nosniff")
    response.headers.setdefault("Referrer-Policy", "no-referrer")  # the token stays out of Referer headers
    return response


def _local_name(name: str) -> bool:
    """An IP address literal, localhost, or this machine's own host name."""
    try:
        ipaddress.ip_address(name)
        return True
    except ValueError:
        pass
    own = {socket.gethostname().lower(), socket.getfqdn().lower()}
    return name.lower() in {"localhost", *own, *(f"{n}.local" for n in own)}


def reachable_address() -> str:
    """This machine's address on its network (the interface a packet to the outside would leave by; nothing is
    sent), or 127.0.0.1 when it has none."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))  # TEST-NET-1: routable form, never answered
            return probe.getsockname()[0]
        except OSError:
            return "127.0.0.1"


def _no_password() -> str:
    raise ServerError(
        "the TLS key is encrypted: give a key without a passphrase (openssl rsa -in key.pem -out plain.pem)"
    )


def _ssl_context(cert: str | Path | None, key: str | Path | None) -> ssl.SSLContext | None:
    if cert is None and key is None:
        return None
    if cert is None or key is None:
        raise ServerError("TLS needs both --cert and --key")
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    try:
        ctx.load_cert_chain(str(cert), str(key), password=_no_password)  # never a prompt on the terminal
    except (OSError, ssl.SSLError) as exc:
        raise ServerError(f"cannot load the TLS certificate {cert} / key {key}: {exc}") from exc
    return ctx
