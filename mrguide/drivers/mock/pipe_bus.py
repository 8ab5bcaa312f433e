"""A CAN link between two processes of one machine: python-can's `mrguide_pipe` interface.

python-can's `virtual` bus lives inside one process, so a dry run's simulated drives shared the master's
interpreter (and its GIL) and their work ran in the master's control period. This interface carries the frames
over a Unix socket pair instead: each end is a bus of its own process, frames arrive in order and none is lost
(a `SOCK_SEQPACKET` socket keeps each frame one message), and a node never receives its own frames. The channel
is the file descriptor of one end in the process that opens the bus::

    master_end, device_end = pipe_link()
    bus = can.Bus(interface="mrguide_pipe", channel=str(master_end.fileno()))

The bus works on a duplicate of that descriptor (closing the bus leaves the caller's socket open). Frames are
stamped when they are received, as a CAN controller stamps them. Classic CAN frames only (no CAN FD).
"""

from __future__ import annotations

import os
import select
import socket
import struct
import time
from typing import Any

import can

from mrguide.drivers.bus import stop_periodic_tasks

#: arbitration ID, flags, DLC, 8 data bytes.
FRAME = struct.Struct("<IBB8s")
_EXTENDED, _REMOTE, _ERROR = 1, 2, 4


def pipe_link() -> tuple[socket.socket, socket.socket]:
    """Two connected ends of a link (a Unix `SOCK_SEQPACKET` socket pair), one for each process."""
    return socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)


def pack(msg: can.Message) -> bytes:
    """One frame as it crosses the link; ValueError for a frame classic CAN cannot carry."""
    if msg.is_fd or len(msg.data) > 8:
        raise ValueError(f"the pipe link carries classic CAN frames only (0x{msg.arbitration_id:X})")
    flags = _EXTENDED * msg.is_extended_id | _REMOTE * msg.is_remote_frame | _ERROR * msg.is_error_frame
    return FRAME.pack(msg.arbitration_id, flags, msg.dlc, bytes(msg.data))


def unpack(packet: bytes, channel: str) -> can.Message:
    """The frame of one packet, stamped now; ValueError if the packet is not one."""
    if len(packet) != FRAME.size:
        raise ValueError(f"a pipe-link packet of {len(packet)} bytes, expected {FRAME.size}")
    can_id, flags, dlc, data = FRAME.unpack(packet)
    remote = bool(flags & _REMOTE)
    return can.Message(
        timestamp=time.time(),
        arbitration_id=can_id,
        is_extended_id=bool(flags & _EXTENDED),
        is_remote_frame=remote,
        is_error_frame=bool(flags & _ERROR),
        dlc=dlc,
        data=b"" if remote else data[: min(dlc, 8)],
        channel=channel,
    )


class PipeBus(can.BusABC):
    """One end of a `pipe_link` as a python-can bus (see the module docstring)."""

    def __init__(self, channel: Any = None, **kwargs: Any) -> None:
        fd = -1
        try:
            fd = os.dup(int(channel))
            sock = socket.socket(fileno=fd)
        except (TypeError, ValueError, OSError) as exc:
            if fd >= 0:
                os.close(fd)
            raise can.CanInitializationError(
                f"mrguide_pipe: channel must be the file descriptor of a pipe_link end, got {channel!r} ({exc})"
            ) from exc
        if sock.family != socket.AF_UNIX or sock.type != socket.SOCK_SEQPACKET:
            sock.close()
            raise can.CanInitializationError(f"mrguide_pipe: descriptor {channel} is not an end of a pipe_link")
        super().__init__(channel=channel, **kwargs)
        self._sock = sock
        self.channel_info = f"pipe link (descriptor {fd})"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        try:
            self._sock.send(pack(msg))
        except ValueError as exc:
            raise can.CanOperationError(str(exc)) from exc
        except OSError as exc:
            raise can.CanOperationError(f"pipe link: send failed: {exc}") from exc

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            readable, _, _ = select.select([self._sock], [], [], timeout)
            if not readable:
                return None, False
            packet = self._sock.recv(FRAME.size + 1)
        except OSError as exc:
            raise can.CanOperationError(f"pipe link: receive failed: {exc}") from exc
        if not packet:
            raise can.CanOperationError("pipe link: the other end closed")
        try:
            return unpack(packet, self.channel_info), False
        except ValueError as exc:
            raise can.CanOperationError(str(exc)) from exc

    def fileno(self) -> int:
        return self._sock.fileno()

    def shutdown(self) -> None:
        stop_periodic_tasks(self)  # before the socket closes under a task mid-send
        super().shutdown()
        self._sock.close()
