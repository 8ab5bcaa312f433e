"""The annotation broker: between one trainer asking for waypoints and any number of clients answering.

Thread-safe and free of web code. The trainer's thread calls `request`, which blocks until an answer,
a skip, the timeout, or an interrupt; the server's thread calls `attach`, `receive` and `detach` for
each client. Messages to a client go through the `send` callable given at `attach`, which must not
block (the server queues them into its event loop); they are queued under the broker's lock, so every
client sees them in the order the broker decided them. Nothing a client sends can raise here: every
refusal becomes an `ack` with its code and reason, and is counted under its code (protocol.REFUSALS).

An answer is acknowledged once the trainer has it on disk (`acknowledge`, after the annotation log's fsync),
unless `request(..., acknowledge=True)` acknowledges it at once. A claim expires when its client has sent
nothing (no answer, no ping) for `claim_timeout_s`: the request is open to every client again.
"""

from __future__ import annotations

import collections
import itertools
import logging
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrguide.annotation.protocol import (
    REFUSALS,
    AnnotationRequest,
    ProtocolError,
    parse_answer,
    parse_hello,
    parse_message,
)
from mrguide.robot import Workspace

log = logging.getLogger(__name__)

Send = Callable[[dict[str, Any]], None]
#: How often a waiting `request` wakes up (so Ctrl-C and expired claims are handled promptly), s.
POLL_S = 0.05
#: A claimant that sends nothing for this long loses its claim (s; `mrguide train --claim-timeout`).
CLAIM_TIMEOUT_S = 60.0


@dataclass(frozen=True)
class LiveAnswer:
    """An accepted answer: the marked TCP target and vacuum command, who gave it and how fast."""

    request_id: str
    target: np.ndarray
    vacuum: bool
    client_id: str
    client: str
    latency_s: float
    here: bool = False  # "not there — here": the person teaches the point


@dataclass(frozen=True)
class NoAnswer:
    """A request that ended without an answer: `reason` is "timeout", "skipped" or "shutdown"."""

    request_id: str
    reason: str


@dataclass
class _Client:
    client_id: str
    send: Send
    kind: str = "unknown"
    name: str = "unknown"
    last_seen: float = field(default_factory=time.monotonic)  # its last message of any kind


@dataclass
class _Pending:
    request_id: str
    message: dict[str, Any]
    created: float
    deadline: float | None
    claimed_by: str | None = None
    result: LiveAnswer | NoAnswer | None = None


@dataclass
class BrokerStats:
    """Counters shown in `status` and printed at the end of a run."""

    requests: int = 0
    answered: int = 0
    timeouts: int = 0
    skipped: int = 0
    claims_expired: int = 0
    interventions: int = 0  # a person stepped in ("intervene"), counted when the trainer took it up
    refused: collections.Counter = field(default_factory=collections.Counter)  # by code, protocol.REFUSALS


class AnnotationBroker:
    """One outstanding request at a time; first claim wins; answers validated against the workspace."""

    def __init__(
        self, workspace: Workspace, hello: dict[str, Any] | None = None, claim_timeout_s: float = CLAIM_TIMEOUT_S
    ):
        self.workspace = workspace
        self.claim_timeout_s = claim_timeout_s
        self._hello = dict(hello or {})
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._clients: dict[str, _Client] = {}
        self._ids = itertools.count(1)
        self._session = secrets.token_hex(8)  # 64 bits: a resumed run's ids never meet an earlier run's
        self._seq = itertools.count(1)
        self._pending: _Pending | None = None
        self._status: dict[str, Any] = {"type": "status", "waiting": False}
        self._closed = threading.Event()  # an Event, not a flag under the lock: close() may run in a signal handler
        self._intervene: str | None = None  # the client that asked to step in, until the trainer takes it up
        self.stats = BrokerStats()
        self.on_waiting: Callable[[bool], None] | None = None

    # -- trainer side ------------------------------------------------------------------------------
    def request(
        self, req: AnnotationRequest, timeout: float | None = None, acknowledge: bool = True
    ) -> LiveAnswer | NoAnswer:
        """Ask every client; block until an answer, a skip, `timeout` seconds (None: no limit) or shutdown. An
        answer is acknowledged to its client at once, or with `acknowledge=False` when the caller calls
        `acknowledge(answer)` (once it has recorded it)."""
        with self._lock:
            if self._pending is not None:
                raise RuntimeError("an annotation request is already outstanding")
            request_id = f"{self._session}-{next(self._seq)}"
            now = time.monotonic()
            pending = _Pending(
                request_id, req.to_message(request_id, timeout, None), now, None if timeout is None else now + timeout
            )
            self.stats.requests += 1
            if self._closed.is_set():
                return NoAnswer(request_id, "shutdown")
            self._pending = pending
            status = self._status_changed(waiting=True)  # with the request, under one lock: a hello has both or none
            self._deliver([(c, m) for c in self._clients.values() for m in (pending.message, status)])
        self._waiting_changed(True)
        try:
            with self._lock:
                while pending.result is None:
                    if self._closed.is_set():
                        pending.result = NoAnswer(request_id, "shutdown")
                        break
                    if pending.deadline is not None and time.monotonic() >= pending.deadline:
                        self.stats.timeouts += 1
                        pending.result = NoAnswer(request_id, "timeout")
                        break
                    self._expire_claim(pending)
                    self._changed.wait(POLL_S)
                result = pending.result
        finally:
            if acknowledge and isinstance(pending.result, LiveAnswer):
                self.acknowledge(pending.result)  # before the cancel: the answerer learns first that it was taken
            self._finish(pending)
        return result

    def acknowledge(self, answer: LiveAnswer) -> None:
        """Tell the answering client its answer was taken (call once it is recorded)."""
        with self._lock:
            self._reply(answer.client_id, _ack("answer", answer.request_id, True, None))

    def _expire_claim(self, pending: _Pending) -> None:
        """Release the claim of a claimant that has sent nothing for claim_timeout_s (lock held)."""
        client = self._clients.get(pending.claimed_by) if pending.claimed_by else None
        if client is None or time.monotonic() - client.last_seen < self.claim_timeout_s:
            return
        log.info(
            "annotation client %s claimed request %s and went quiet: claim released",
            client.client_id,
            pending.request_id,
        )
        self.stats.claims_expired += 1
        pending.claimed_by = None
        pending.message["claimed_by"] = None
        self._deliver(
            [
                (c, {"type": "claimed", "id": pending.request_id, "client_id": None, "reason": "expired"})
                for c in self._clients.values()
            ]
        )

    def _finish(self, pending: _Pending) -> None:
        """Close the request (also on KeyboardInterrupt) and tell the clients why."""
        with self._lock:
            if self._pending is pending:
                self._pending = None
            r = pending.result
            reason = "interrupted" if r is None else ("answered" if isinstance(r, LiveAnswer) else r.reason)
            cancel = {"type": "cancel", "id": pending.request_id, "reason": reason}
            status = self._status_changed(waiting=False)
            self._deliver([(c, m) for c in self._clients.values() for m in (cancel, status)])
        self._waiting_changed(False)

    def take_intervention(self) -> str | None:
        """The client that asked to step in since the last call (and forget it), or None."""
        with self._lock:
            client, self._intervene = self._intervene, None
            if client is not None:
                self.stats.interventions += 1
            return client

    def publish_status(self, **fields: Any) -> None:
        """Update the training status and push it to every client."""
        with self._lock:
            msg = self._status_changed(**fields)
            self._deliver([(c, msg) for c in self._clients.values()])

    def close(self) -> None:
        """End any outstanding request (as `shutdown`) and refuse new ones.

        Safe from a signal handler that interrupted a thread holding the lock: it never blocks on the
        lock, and a waiting `request` sees the closure within POLL_S.
        """
        self._closed.set()
        if self._lock.acquire(blocking=False):
            try:
                self._changed.notify_all()
            finally:
                self._lock.release()

    @property
    def client_count(self) -> int:
        with self._lock:
            return len(self._clients)

    @property
    def waiting(self) -> bool:
        with self._lock:
            return self._pending is not None

    # -- client side -------------------------------------------------------------------------------
    def attach(self, send: Send) -> str:
        """Register a client; it gets `hello` with the status and the outstanding request, if any."""
        with self._lock:
            client = _Client(f"c{next(self._ids)}", send)
            self._clients[client.client_id] = client
            self._status["clients"] = len(self._clients)
            hello = {
                "type": "hello",
                "protocol": 1,
                "client_id": client.client_id,
                **self._hello,
                "status": self._status_message(),
                "request": self._outstanding(),
            }
            self._deliver([(client, hello)])
            status = self._status_message()
            self._deliver([(c, status) for c in self._clients.values() if c is not client])
        log.info("annotation client %s connected", client.client_id)
        return client.client_id

    def detach(self, client_id: str) -> None:
        """Forget a client; a request it had claimed is open again."""
        with self._lock:
            self._clients.pop(client_id, None)
            self._status["clients"] = len(self._clients)
            status = self._status_message()
            self._deliver([(c, status) for c in self._clients.values()])
            p = self._pending
            if p is not None and p.claimed_by == client_id:
                p.claimed_by = None
                p.message["claimed_by"] = None
                self._deliver(
                    [(c, {"type": "claimed", "id": p.request_id, "client_id": None}) for c in self._clients.values()]
                )
        log.info("annotation client %s disconnected", client_id)

    def receive(self, client_id: str, text: str | bytes) -> bool:
        """Handle one message from a client; never raises. Replies are queued in order, under the lock. Returns
        False when the connection is to be closed (a hello of another protocol version)."""
        kind, msg_id = None, None
        with self._lock:
            client = self._clients.get(client_id)
            if client is not None:
                client.last_seen = time.monotonic()
            try:
                msg = parse_message(text)
                kind, msg_id = msg["type"], msg.get("id")
                self._handle(client_id, kind, msg)
            except ProtocolError as exc:
                self.stats.refused[exc.code] += 1
                self._reply(
                    client_id, _ack(kind, msg_id if isinstance(msg_id, str) else None, False, str(exc), exc.code)
                )
                return exc.code != "unsupported_protocol"
            except Exception as exc:  # a bug here must not take the server or the trainer down
                log.error("annotation broker failed on a message from %s: %s: %s", client_id, type(exc).__name__, exc)
                self.stats.refused["internal"] += 1
                self._reply(client_id, _ack(kind, None, False, f"internal error: {type(exc).__name__}", "internal"))
        return True

    def _handle(self, client_id: str, kind: str, msg: dict[str, Any]) -> None:
        """Act on a parsed message (lock held); refusals raise ProtocolError."""
        client = self._clients.get(client_id)
        if client is None:
            return
        if kind == "hello":
            client.kind, client.name = parse_hello(msg)
            self._reply(client_id, _ack("hello", None, True, None))
            return
        if kind == "ping":
            self._reply(client_id, _ack("ping", None, True, None))
            return
        if kind == "intervene":  # step in now: the trainer cuts the agent's episode and asks for a demonstration
            if self._pending is not None:
                raise ProtocolError("stale", "a demonstration is already being asked for: answer it")
            self._intervene = client_id
            self._reply(client_id, _ack("intervene", None, True, None))
            return
        target = parse_answer(msg, self.workspace) if kind == "answer" else None
        p = self._pending
        if p is None or p.result is not None or msg["id"] != p.request_id:
            raise ProtocolError("stale", "stale request id: no such request is outstanding")
        if p.claimed_by not in (None, client_id):
            raise ProtocolError("claimed", f"claimed by {p.claimed_by}")
        if target is None:  # an answer is acknowledged once it is recorded (`acknowledge`)
            self._reply(client_id, _ack(kind, p.request_id, True, None))
        if p.claimed_by is None:
            p.claimed_by = client_id
            p.message["claimed_by"] = client_id
            self._deliver(
                [(c, {"type": "claimed", "id": p.request_id, "client_id": client_id}) for c in self._clients.values()]
            )
        if target is not None:
            p.result = LiveAnswer(
                p.request_id, target[0], target[1], client_id, client.kind, time.monotonic() - p.created, target[2]
            )
            self.stats.answered += 1
        elif kind == "skip":
            p.result = NoAnswer(p.request_id, "skipped")
            self.stats.skipped += 1
        self._changed.notify_all()

    def _reply(self, client_id: str, msg: dict[str, Any]) -> None:
        client = self._clients.get(client_id)
        if client is not None:
            self._deliver([(client, msg)])

    # -- helpers -----------------------------------------------------------------------------------
    def _outstanding(self) -> dict[str, Any] | None:
        """The open request as a (re)connecting client should see it: with the seconds left to answer."""
        p = self._pending
        if p is None or p.result is not None:
            return None
        remaining = None if p.deadline is None else round(max(0.0, p.deadline - time.monotonic()), 3)
        return {**p.message, "remaining_s": remaining}

    def _status_message(self) -> dict[str, Any]:
        refused = {code: self.stats.refused[code] for code in REFUSALS if self.stats.refused[code]}
        return {**self._status, "type": "status", "refused": refused, "claims_expired": self.stats.claims_expired}

    def _status_changed(self, **fields: Any) -> dict[str, Any]:
        """Update the training status (lock held); the status message to send."""
        self._status.update(fields)
        return self._status_message()

    def _waiting_changed(self, waiting: bool) -> None:
        """Tell `on_waiting` (outside the lock: it is the caller's code)."""
        if self.on_waiting is not None:
            self.on_waiting(waiting)

    @staticmethod
    def _deliver(out: list[tuple[_Client, dict[str, Any]]]) -> None:
        for client, msg in out:
            try:
                client.send(msg)
            except Exception:  # a dead connection is the server's to clean up
                log.debug("could not queue a message for %s", client.client_id, exc_info=True)


def _ack(
    kind: str | None, request_id: str | None, accepted: bool, reason: str | None, code: str | None = None
) -> dict[str, Any]:
    return {"type": "ack", "for": kind, "id": request_id, "accepted": accepted, "reason": reason, "code": code}
