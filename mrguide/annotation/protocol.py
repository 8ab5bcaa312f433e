"""Live annotation protocol v1 (docs/annotation-protocol.md): message parsing and validation, requests.

Pure functions and data: no threads, no web code. Every refusal is a `ProtocolError` whose message is
the reason sent back to the client.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrguide.robot import Workspace
from mrguide.task import G_REQUIRED, PHASES

PROTOCOL_VERSION = 1
MAX_MESSAGE_BYTES = 64 * 1024
CLIENT_TYPES = ("hello", "claim", "answer", "skip", "ping", "intervene")

#: What is asked in each phase, in words a person at the page or in the headset understands.
PROMPTS: tuple[str, ...] = (
    "Mark the pre-grasp point: where the cup should hover above the object before it goes down. Vacuum off.",
    "Mark where the cup should touch the object: the centre of its top face, or press Exactly here (H) and click"
    " the point where it must grip. Vacuum on.",
    "Mark where the cup should lift the object to. Vacuum on.",
    "Mark where to carry the object: the point above the goal. Vacuum on.",
    "Mark where the object should be set down on the goal; the vacuum releases there. Vacuum off.",
)
REMARK_PROMPT = "The arm did not reach your last mark for this step. Mark it again. "


#: Why a client message is refused: the `code` of its `ack`, and the keys of the refusal counts in `status`
#: (a fixed set, whatever a client sends).
REFUSALS = (
    "malformed",
    "too_large",
    "binary",
    "not_an_object",
    "no_type",
    "unknown_type",
    "no_id",
    "bad_hello",
    "unsupported_protocol",
    "stale",
    "claimed",
    "bad_target",
    "not_finite",
    "outside_workspace",
    "bad_vacuum",
    "bad_here",
    "internal",
)
#: The most digits a number may have (a longer one is refused before Python turns it into an int).
MAX_DIGITS = 18
#: Reasons are cut to this many characters (they may quote a piece of the message).
MAX_REASON = 160


class ProtocolError(ValueError):
    """A client message that is refused: `code` (one of REFUSALS) and the reason sent back in the `ack`."""

    def __init__(self, code: str, reason: str):
        assert code in REFUSALS, code
        super().__init__(reason[:MAX_REASON])
        self.code = code


@dataclass(frozen=True)
class AnnotationRequest:
    """What the trainer asks a person: the robot and scene state in one phase of the task."""

    phase: int
    joints: np.ndarray  # rad, robot joint order
    tcp: np.ndarray  # m, robot base frame
    vacuum_on: bool
    object_position: np.ndarray
    object_orientation: np.ndarray  # quaternion x, y, z, w
    goal: np.ndarray
    obs: np.ndarray  # the policy observation the answer is recorded with
    remark: bool = False
    previous_target: np.ndarray | None = None

    def to_message(self, request_id: str, timeout_s: float | None, claimed_by: str | None) -> dict[str, Any]:
        """The `request` message (JSON-ready)."""
        return {
            "type": "request",
            "id": request_id,
            "phase": PHASES[self.phase],
            "phase_index": self.phase,
            "ask": ["target", "vacuum"],
            "prompt": (REMARK_PROMPT if self.remark else "") + PROMPTS[self.phase],
            "suggested_vacuum": G_REQUIRED[self.phase] > 0,
            "remark": self.remark,
            "previous_target": _floats(self.previous_target) if self.previous_target is not None else None,
            "state": {
                "joints": _floats(self.joints),
                "tcp": _floats(self.tcp),
                "vacuum_on": bool(self.vacuum_on),
                "object": {"position": _floats(self.object_position), "orientation": _floats(self.object_orientation)},
                "goal": _floats(self.goal),
            },
            "timeout_s": timeout_s,
            "claimed_by": claimed_by,
        }


def _floats(x: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(x).ravel()]


def _refuse_constant(name: str) -> float:
    raise ProtocolError("not_finite", f"not finite: {name} is not allowed in JSON")


def _integer(digits: str) -> int:
    if len(digits.lstrip("-")) > MAX_DIGITS:
        raise ProtocolError("too_large", f"a number with more than {MAX_DIGITS} digits")
    return int(digits)


def parse_message(text: str | bytes) -> dict[str, Any]:
    """Decode one client message: a JSON object of known `type` within the size limit."""
    if isinstance(text, (bytes, bytearray)):
        raise ProtocolError("binary", "binary frames are not part of the protocol; send JSON text")
    if len(text.encode("utf-8", "surrogatepass")) > MAX_MESSAGE_BYTES:
        raise ProtocolError("too_large", f"message larger than {MAX_MESSAGE_BYTES} bytes")
    try:
        msg = json.loads(text, parse_constant=_refuse_constant, parse_int=_integer)
    except json.JSONDecodeError as exc:
        raise ProtocolError("malformed", f"malformed JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from exc
    except RecursionError as exc:
        raise ProtocolError("malformed", "malformed JSON: nested too deeply") from exc
    if not isinstance(msg, dict):
        raise ProtocolError("not_an_object", f"a message must be a JSON object, got {type(msg).__name__}")
    kind = msg.get("type")
    if not isinstance(kind, str):
        raise ProtocolError("no_type", "message has no string field 'type'")
    if kind not in CLIENT_TYPES:
        raise ProtocolError("unknown_type", f"unknown message type {kind[:40]!r}")
    if kind in ("claim", "answer", "skip") and not isinstance(msg.get("id"), str):
        raise ProtocolError("no_id", f"'{kind}' needs a string field 'id'")
    return msg


def parse_hello(msg: dict[str, Any]) -> tuple[str, str]:
    """(client kind, display name) of a client `hello`; another protocol version (or a version that is not a
    whole number: JSON's `true` is no 1) is refused with "unsupported_protocol", and the server then closes the
    connection."""
    version = msg.get("protocol")
    if isinstance(version, bool) or not isinstance(version, int) or version != PROTOCOL_VERSION:
        raise ProtocolError(
            "unsupported_protocol",
            f"protocol {repr(version)[:20]} not supported: this server speaks {PROTOCOL_VERSION}",
        )
    kind = msg.get("client", "unknown")
    name = msg.get("name", kind)
    if not isinstance(kind, str) or not isinstance(name, str):
        raise ProtocolError("bad_hello", "'client' and 'name' must be strings")
    return kind[:40], name[:80]


def parse_answer(msg: dict[str, Any], workspace: Workspace) -> tuple[np.ndarray, bool, bool]:
    """(target in m, vacuum on, here) of an `answer`: three finite numbers inside the workspace box, a bool, and an
    optional bool (default false): "not there — here", the person teaches the point (`MarkFusion.teach`)."""
    target = msg.get("target")
    if not isinstance(target, list) or len(target) != 3:
        raise ProtocolError("bad_target", "'target' must be a list of 3 numbers [x, y, z] in metres")
    for i, v in enumerate(target):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ProtocolError("bad_target", f"target[{i}] is not a number: {v!r}"[:120])
        if not math.isfinite(v):
            raise ProtocolError("not_finite", f"not finite: target[{i}]")
    vacuum = msg.get("vacuum")
    if not isinstance(vacuum, bool):
        raise ProtocolError("bad_vacuum", "'vacuum' must be true or false")
    here = msg.get("here", False)
    if not isinstance(here, bool):
        raise ProtocolError("bad_here", "'here' must be true or false (or absent)")
    p = np.array(target, dtype=float)
    for i, axis in enumerate("xyz"):
        if p[i] < workspace.lo[i]:
            raise ProtocolError(
                "outside_workspace", f"target outside the workspace box: {axis} = {p[i]:.4f} < {workspace.lo[i]:.4f}"
            )
        if p[i] > workspace.hi[i]:
            raise ProtocolError(
                "outside_workspace", f"target outside the workspace box: {axis} = {p[i]:.4f} > {workspace.hi[i]:.4f}"
            )
    return p, vacuum, here
