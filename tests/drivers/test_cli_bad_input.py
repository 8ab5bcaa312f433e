"""`mrguide bus selftest|monitor` with a bad bus description or option: one line naming file and key, exit 2.

Every case is refused while the bus description is loaded, before a simulated device or the master
starts (both would read the EDS files and build one drive per `[[joints]]`).
"""

from __future__ import annotations

import pytest

from mrguide.drivers.config import EDS_DIR
from mrguide.drivers.mock import sim_cobot

SIX_JOINTS = "[[joints]]\n" * 6
DRIVE_EDS = (EDS_DIR / "cia402_drive.eds").read_text()
CORRUPT_EDS = "[FileInfo]\nFileName=x\n[1000\nfoo"


def _without_object(eds: str, index: str) -> str:
    """The EDS text without object `index` (e.g. "607A") and its sub-indices."""
    out, skip = [], False
    for line in eds.splitlines():
        if line.startswith("["):
            skip = line[1:5].upper() == index and (line[5] == "]" or line[5:8] == "sub")
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"


def _eds(tmp_path, name: str, text: str | bytes) -> str:
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return str(path)


CASES = [
    # (id, TOML of the bus description given the tmp dir, words in the one stderr line)
    (
        "five joints",
        lambda d: SIX_JOINTS.rsplit("[[joints]]", 1)[0],
        ["bus.toml", "joints: 5 drives configured", "6 joints"],
    ),
    ("seven joints", lambda d: SIX_JOINTS + "[[joints]]\n", ["bus.toml", "7 drives"]),
    (
        "not an EDS",
        lambda d: f'[drives]\neds = "{_eds(d, "x.eds", "garbage")}"\n',
        ["drives.eds", "x.eds", "not a readable EDS file"],
    ),
    (
        "corrupt EDS",
        lambda d: f'[drives]\neds = "{_eds(d, "x.eds", CORRUPT_EDS)}"\n',
        ["drives.eds", "x.eds", "not a readable EDS file"],
    ),
    (
        "binary EDS",
        lambda d: f'[vacuum]\neds = "{_eds(d, "x.eds", bytes(range(256)) * 4)}"\n',
        ["vacuum.eds", "x.eds", "not a readable EDS file"],
    ),
    (
        "EDS of another format",
        lambda d: f'[drives]\neds = "{_eds(d, "x.toml", "a = 1")}"\n',
        ["drives.eds", "x.toml", "not a readable EDS file"],
    ),
    (
        "EDS without the target",
        lambda d: f'[drives]\neds = "{_eds(d, "x.eds", _without_object(DRIVE_EDS, "607A"))}"\n',
        ["drives.eds", "x.eds", "lacks object(s) 0x607A"],
    ),
    (
        "vacuum EDS for the drives",
        lambda d: '[drives]\neds = "vacuum_generator.eds"\n',
        ["drives.eds", "vacuum_generator.eds", "0x6040"],
    ),
    ("missing EDS", lambda d: '[vacuum]\neds = "nope.eds"\n', ["vacuum.eds", "nope.eds", "not found"]),
    (
        "unknown option",
        lambda d: "[bus]\noptions = { recieve_own_messages = true }\n",
        ["bus.toml", "bus.options", "recieve_own_messages", "'virtual'", "receive_own_messages"],
    ),
    (
        "option for another interface",
        lambda d: "[bus]\noptions = { tty_baudrate = 115200 }\n",
        ["bus.options", "tty_baudrate"],
    ),
    (
        "non-finite option",
        lambda d: "[bus]\noptions = { rx_queue_size = inf }\n",
        ["bus.options: 'rx_queue_size' = inf"],
    ),
    ("wrong-typed number", lambda d: '[timing]\nboot_timeout = "3 s"\n', ["bus.toml", "timing.boot_timeout", "'3 s'"]),
    ("boot timeout nan", lambda d: "[timing]\nboot_timeout = nan\n", ["bus.toml", "timing.boot_timeout = nan"]),
    ("enable timeout inf", lambda d: "[timing]\nenable_timeout = inf\n", ["timing.enable_timeout = inf"]),
    ("unknown key", lambda d: "[timing]\nboot_timout = 3.0\n", ["bus.toml", "boot_timout"]),
    ("gear ratio 0", lambda d: "[[joints]]\ngear_ratio = 0\n" + "[[joints]]\n" * 5, ["joints (node 3).gear_ratio = 0"]),
]


@pytest.fixture
def no_devices(monkeypatch):
    """Fail the test if simulated devices are created."""

    def started(*args, **kwargs):
        raise AssertionError("simulated devices were created before the bus description was refused")

    monkeypatch.setattr(sim_cobot.SimulatedCobot, "__init__", started)


@pytest.mark.parametrize("command", ["selftest", "monitor"])
@pytest.mark.parametrize("make_toml, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_bus_description_is_refused_at_load(tmp_path, run_cli, no_devices, command, make_toml, words):
    path = tmp_path / "bus.toml"
    path.write_text(
        f'[bus]\nchannel = "bad-input-{command}"\n' * ("[bus]" not in make_toml(tmp_path)) + make_toml(tmp_path)
    )
    argv = ["bus", command, "--config", path] + (["--simulate", "--duration", "0.1"] if command == "monitor" else [])
    line = run_cli(argv).assert_refused(*words)
    assert line.startswith(f"mrguide bus {command}: ")


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "1s", ""])
def test_monitor_duration_must_be_a_positive_number(run_cli, no_devices, value):
    run_cli(["bus", "monitor", "--duration", value, "--simulate"]).assert_refused("--duration")
