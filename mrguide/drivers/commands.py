"""`mrguide bus selftest` and `mrguide bus monitor`: argparse wiring for the top-level CLI.

The top-level `mrguide` parser calls `add_bus_commands(subparsers)`; each command stores a handler in
`func` that takes the parsed arguments and returns the process exit code. The handlers import the driver
(python-can, canopen) themselves: the parser is built without it. Bad input raises ConfigError (or another
InputError) and a bus fault DriverError: `mrguide.cli.main` turns them into one line on stderr and exit 2
or 1.
"""

from __future__ import annotations

import argparse
import logging
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mrguide.cli_args import positive_float
from mrguide.config import ConfigError
from mrguide.drivers.errors import DriverError

if TYPE_CHECKING:
    from mrguide.drivers.config import CobotBusConfig
    from mrguide.robot import RobotSpec

logger = logging.getLogger(__name__)

EXIT_FAILED = 1
#: Demo motion while monitoring a simulated cobot: amplitude (rad) and period (s) of a sine per joint.
DEMO_AMPLITUDE = 0.05
DEMO_PERIOD = 2.0


def add_bus_commands(subparsers: argparse._SubParsersAction) -> None:
    """Add `bus selftest` and `bus monitor` to the top-level `mrguide` parser."""
    bus = subparsers.add_parser(
        "bus",
        help="CAN bus of the cobot: self-test and traffic monitor",
        description="CAN bus of the cobot (CiA 402 joint drives + vacuum generator).",
    )
    commands = bus.add_subparsers(dest="bus_command", metavar="{selftest,monitor}", required=True)

    selftest = commands.add_parser(
        "selftest",
        help="boot, enable, move each joint a little, toggle the vacuum, report",
        description="Boot the cobot (simulated devices on the virtual bus, the real cobot otherwise), enable "
        "the drives, move each joint 0.05 rad and back, toggle the vacuum and print a report.",
    )
    _add_config(selftest)
    selftest.add_argument(
        "--allow-motion",
        action="store_true",
        help="required on a real bus: confirms the arm may move each joint by 0.05 rad",
    )
    selftest.set_defaults(func=_selftest_command, command_name="bus selftest")

    mon = commands.add_parser(
        "monitor",
        help="decode live CAN traffic into readable lines",
        description="Print NMT, SYNC, PDO, SDO, EMCY and heartbeat frames as readable lines.",
    )
    _add_config(mon)
    mon.add_argument("--duration", type=positive_float, default=2.0, help="seconds to monitor (default: 2)")
    mon.add_argument(
        "--simulate",
        action="store_true",
        help="virtual bus only: run the simulated cobot and a master streaming a small motion meanwhile",
    )
    mon.set_defaults(func=_monitor_command, command_name="bus monitor")


def _add_config(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        help="bus description TOML, e.g. configs/devices/cobot_bus.toml (default: built-in defaults, virtual bus)",
    )
    parser.add_argument(
        "--robot",
        default="",
        help="the arm whose drives are on the bus: a shipped arm's name (ur5, ur10) or an arm file "
        "(.toml); it gives the node IDs, the number of drives and the limits (default: ur5)",
    )


def _robot(args: argparse.Namespace) -> RobotSpec:
    """The arm named by --robot: a shipped arm's name, or a path to an arm file."""
    from mrguide.robot import RobotConfig, load_robot

    text = args.robot
    return load_robot(RobotConfig(file=text) if text.endswith(".toml") or "/" in text else RobotConfig(name=text))


def _selftest_command(args: argparse.Namespace) -> int:
    from mrguide.drivers.config import load_cobot_bus_config
    from mrguide.drivers.selftest import run_selftest

    robot = _robot(args)
    config = load_cobot_bus_config(args.config, robot)
    if config.bus.interface != "virtual" and not args.allow_motion:
        raise ConfigError(
            f"bus interface {config.bus.interface!r} is a real bus: the selftest moves every "
            "joint; pass --allow-motion to confirm"
        )
    return 0 if run_selftest(config, robot, print) else EXIT_FAILED


def _monitor_command(args: argparse.Namespace) -> int:
    from mrguide.drivers.config import load_cobot_bus_config
    from mrguide.drivers.monitor import monitor
    from mrguide.drivers.realtime import settled_heap

    robot = _robot(args)
    config = load_cobot_bus_config(args.config, robot)
    if args.simulate and config.bus.interface != "virtual":
        raise ConfigError("--simulate needs the virtual bus: simulated devices must not join a real bus")
    demo = _SimulatedDemo(config, robot) if args.simulate else None
    with settled_heap():  # no full garbage collection pauses the monitor's receiver or the demo's control cycle
        try:
            counts = monitor(config, robot.joint_names, args.duration, print, demo.start if demo else None)
        finally:
            if demo is not None:
                demo.stop()
    total = sum(counts.values())
    summary = ", ".join(f"{kind} {n}" for kind, n in sorted(counts.items()))
    print(f"{total} frames in {args.duration:g} s ({summary or 'no traffic'})")
    return 0


class _SimulatedDemo:
    """Simulated cobot plus a master that boots it and streams a slow sine on every joint."""

    def __init__(self, config: CobotBusConfig, robot: RobotSpec) -> None:
        from mrguide.drivers.mock.first_order_plant import FirstOrderPlant
        from mrguide.drivers.mock.sim_cobot import SimulatedCobot, shared_pc_config

        self._config = config = shared_pc_config(config)
        self._robot = robot
        self._sim = SimulatedCobot(config, FirstOrderPlant(self._robot.q_home))
        self._stop = threading.Event()
        self._streaming = threading.Event()
        self._thread = threading.Thread(target=self._master, name="mrguide-bus-demo", daemon=True)

    def start(self) -> None:
        """Boot the devices and the master; return once the master streams (the monitor's duration then counts from
        there, however long a busy machine took to boot: the boot's frames wait in the monitor's queue), or once it
        gave up."""
        self._sim.start()
        self._thread.start()
        timing = self._config.timing
        self._streaming.wait(2 * timing.boot_timeout + timing.enable_timeout)

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        self._sim.stop()

    def _master(self) -> None:
        from mrguide.drivers.cobot import Cobot

        try:
            with Cobot(self._config, self._robot) as cobot:
                cobot.enable()
                self._streaming.set()
                q0, t = cobot.setpoint, 0.0
                while not self._stop.is_set():
                    t += cobot.period
                    cobot.stream(q0 + DEMO_AMPLITUDE * np.sin(2 * np.pi * t / DEMO_PERIOD) ** 2)
                    cobot.set_vacuum(bool(np.sin(2 * np.pi * t / DEMO_PERIOD) > 0))
        except DriverError as exc:
            logger.error("monitor demo master stopped: %s", exc)
        finally:
            self._streaming.set()
