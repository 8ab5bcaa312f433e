"""A dry run's simulated cell in a process of its own: the plant and the simulated devices beside the deploy stack,
as a real cell's drives are beside the robot PC.

In one process the simulated drives' SYNC handling and the plant's physics step ran on the master's interpreter:
a long physics step held the GIL while the control thread waited for it, and its control cycle ran past the period
for the simulator's sake, not the stack's. Here the devices and the plant run in a child process (`multiprocessing`'s
spawn start method), the CAN frames cross a `pipe_link` (python-can's `mrguide_pipe` interface), and what the deploy
side reads of the cell (the part's pose for the exact, camera and HMD pose sources) or does to it (the feeder placing
the next part) is a call to the child through a `multiprocessing` manager::

    with cell_process(env_cfg, bus_cfg, seed) as (plant, master_bus_cfg):
        with Cobot(master_bus_cfg, spec) as cobot:   # the master on its end of the link
            ...
            plant.place_objects(part, goal)

Faults are injected in the same process as the devices only (`simulated_cell(..., own_process=False)`).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import multiprocessing.connection
import os
import signal
import socket
import threading
from collections.abc import Iterator
from dataclasses import replace
from multiprocessing.managers import BaseManager, RemoteError
from typing import Any

import numpy as np

from mrguide.cell.config import CellConfig
from mrguide.drivers.config import BusConfig, CobotBusConfig
from mrguide.drivers.errors import DriverError
from mrguide.drivers.mock.pipe_bus import pipe_link

logger = logging.getLogger(__name__)

#: python-can's interface name of the link (pyproject.toml's `can.interface` entry point).
PIPE_INTERFACE = "mrguide_pipe"


def link_bus(bus: BusConfig, end: socket.socket) -> BusConfig:
    """`bus` on one end of a pipe link (its interface options were the virtual bus's)."""
    return replace(bus, interface=PIPE_INTERFACE, channel=str(end.fileno()), options={})


class CellProcessError(DriverError):
    """The simulated cell's process failed to start or cannot be reached."""


class CellServer:
    """In the cell's process: the plant and the simulated devices on the device end of the link, and what the deploy
    side may read of and do to the cell."""

    def __init__(self, env_cfg: CellConfig, bus_cfg: CobotBusConfig, seed: int, end: socket.socket) -> None:
        from mrguide.cell.plants import build_plant
        from mrguide.drivers.mock.sim_cobot import SimulatedCobot
        from mrguide.robot import load_robot

        self.plant, self.scene = build_plant(env_cfg, bus_cfg, load_robot(env_cfg.robot), seed)
        self._end = end
        self.sim = SimulatedCobot(replace(bus_cfg, bus=link_bus(bus_cfg.bus, end)), self.plant, seed=seed)
        self.sim.start()

    def place_objects(self, obj: np.ndarray, goal: np.ndarray) -> None:
        self.plant.place_objects(obj, goal)

    def object_position(self) -> np.ndarray:
        return self.plant.object_position()

    def view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.plant.view()

    def sync_backlog(self) -> float:
        return self.sim.backlog.take()

    def close(self) -> None:
        """The devices leave the link, the plant's world closes."""
        self.sim.stop()
        self._end.close()
        if self.scene is not None:
            self.scene.close()


class CellProxy:
    """The deploy side's handle on the cell's process (a `FedCell`); a call that cannot reach it is a
    `CellProcessError`, which stops a run with its reason as a driver fault does."""

    def __init__(self, server: Any, pid: int) -> None:
        self._server = server
        #: The cell process's PID.
        self.pid = pid

    def place_objects(self, obj: np.ndarray, goal: np.ndarray) -> None:
        self._call("place_objects", obj, goal)

    def object_position(self) -> np.ndarray:
        return self._call("object_position")

    def view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._call("view")

    def sync_backlog(self) -> float:
        """s: how far the cell's world ran behind the wall clock at most since the last call (`sync_backlog`)."""
        return self._call("sync_backlog")

    def _call(self, name: str, *args: Any) -> Any:
        try:
            return getattr(self._server, name)(*args)
        except (EOFError, OSError, RemoteError) as exc:
            raise CellProcessError(f"the simulated cell's process: {name} failed: {exc!r}") from exc


def _start_cell_process() -> None:
    """In the cell's process before it serves: Ctrl-C reaches every process of the terminal's group, and the cell
    must stay while deploy finishes its cycle; and the process ends with the deploy process, however that ends (a
    killed deploy leaves no simulated cell behind)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = multiprocessing.parent_process()
    if parent is not None:
        sentinel = parent.sentinel
        threading.Thread(target=_exit_with, args=(sentinel,), name="cell-parent-watch", daemon=True).start()


def _exit_with(sentinel: int) -> None:
    multiprocessing.connection.wait([sentinel])
    os._exit(0)


class _CellManager(BaseManager):
    """Runs `CellServer`s in its server process."""


_CellManager.register(
    "CellServer", CellServer, exposed=("place_objects", "object_position", "view", "sync_backlog", "close")
)


@contextlib.contextmanager
def _drained(end: socket.socket) -> Iterator[None]:
    """Frames arriving at `end` read and dropped for the block, as a bus drops what no node listens to: a link end
    nobody reads fills after a few hundred frames and blocks its sender, and the cell's devices, booted in its
    constructor, would wait for a master that waits for the constructor (seen on a slow machine: a hung dry run)."""
    done = threading.Event()

    def drain() -> None:
        while not done.is_set():
            try:
                end.recv(64)
            except TimeoutError:
                continue
            except OSError:
                return

    end.settimeout(0.05)
    reader = threading.Thread(target=drain, name="cell-link-drain", daemon=True)
    reader.start()
    try:
        yield
    finally:
        done.set()
        reader.join()
        end.settimeout(None)


@contextlib.contextmanager
def cell_process(env_cfg: CellConfig, bus_cfg: CobotBusConfig, seed: int) -> Iterator[tuple[CellProxy, CobotBusConfig]]:
    """Start the cell's process (plant + simulated devices, booted and waiting in PRE-OPERATIONAL); yield the deploy
    side's handle on it (`CellProxy`) and the bus config of the master's end of the link. The process ends with the
    block."""
    master_end, device_end = pipe_link()
    manager = _CellManager(ctx=multiprocessing.get_context("spawn"))
    manager.start(initializer=_start_cell_process)
    server = None
    try:
        try:
            with _drained(master_end):  # the devices boot (and talk) before the master reads the link
                server = manager.CellServer(env_cfg, bus_cfg, seed, device_end)  # type: ignore[attr-defined]
        except RemoteError as exc:  # its text is the child's traceback: the last line says what failed
            logger.debug("the simulated cell's process failed to start:%s", exc)
            lines = [line for line in str(exc).splitlines() if line.strip(" -")]
            raise CellProcessError(f"the simulated cell's process could not start the cell: {lines[-1]}") from None
        device_end.close()
        pid = manager._process.pid  # type: ignore[attr-defined]
        yield CellProxy(server, pid), replace(bus_cfg, bus=link_bus(bus_cfg.bus, master_end))
    finally:
        device_end.close()
        if server is not None:
            try:
                server.close()
            except (OSError, EOFError, RemoteError) as exc:  # a dead cell process: nothing left to close there
                logger.warning("the simulated cell's process did not close cleanly: %s", exc)
        manager.shutdown()
        master_end.close()
