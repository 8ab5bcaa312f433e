"""`mrguide bus selftest` / `mrguide bus monitor` through argparse, as the top-level CLI wires them."""

from __future__ import annotations

import pytest

from mrguide.cli import main
from tests.selftest_verdict import assert_selftest_ran


def _run(argv):
    return main(argv)


def _toml(tmp_path, text):
    path = tmp_path / "bus.toml"
    path.write_text(text)
    return str(path)


def test_selftest_on_the_virtual_bus_runs_to_its_verdict(tmp_path, capsys):
    config = _toml(tmp_path, '[bus]\nchannel = "cli-selftest"\n[timing]\nheartbeat_period = 0.05\n')
    code = _run(["bus", "selftest", "--config", config])
    out = capsys.readouterr().out
    assert_selftest_ran(code, out)
    assert out.count("and back: max tracking error") == 6
    assert "part gripped: True" in out


def test_monitor_with_simulated_cobot_decodes_traffic(tmp_path, capsys):
    config = _toml(tmp_path, '[bus]\nchannel = "cli-monitor"\n')
    assert _run(["bus", "monitor", "--config", config, "--duration", "0.6", "--simulate"]) == 0
    out = capsys.readouterr().out
    for word in (
        "NMT RESET COMMUNICATION",
        "BOOT-UP",
        "SDO request",
        "SYNC",
        "TPDO1 node 3",
        "statusword=",
        "frames in 0.6 s",
    ):
        assert word in out


@pytest.mark.parametrize(
    "argv_tail, toml, words, exit_code",
    [
        (["selftest"], "[bus]\nbitrate = 7\n", ["mrguide bus selftest: ", "bus.bitrate"], 2),
        (["monitor", "--duration", "0.1"], "[timing\n", ["mrguide bus monitor: ", "not valid TOML"], 2),
        (["selftest"], '[bus]\ninterface = "socketcan"\nchannel = "can9"\n', ["--allow-motion"], 2),
        (["monitor", "--simulate"], '[bus]\ninterface = "socketcan"\nchannel = "can9"\n', ["virtual bus"], 2),
        (
            ["selftest", "--allow-motion"],
            '[bus]\ninterface = "socketcan"\nchannel = "mrguide-no-if"\n',
            ["CAN driver error", "mrguide-no-if"],
            1,
        ),
    ],
)
def test_bad_config_or_bus_gives_one_clear_line_and_nonzero_exit(tmp_path, capsys, argv_tail, toml, words, exit_code):
    config = _toml(tmp_path, toml)
    code = _run(["bus", *argv_tail[:1], "--config", config, *argv_tail[1:]])
    assert code == exit_code
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    for word in words:
        assert word in err


def test_monitor_names_the_drives_by_the_arm_files_node_map(tmp_path, capsys):
    from mrguide.robot import shipped_arms

    arm = tmp_path / "arm.toml"
    arm.write_text(shipped_arms()["ur10"].read_text().replace("wrist_3_joint = 8", "wrist_3_joint = 30"))
    config = _toml(tmp_path, '[bus]\nchannel = "cli-monitor-arm"\n')
    assert _run(["bus", "monitor", "--config", config, "--robot", str(arm), "--duration", "0.6", "--simulate"]) == 0
    out = capsys.readouterr().out
    assert "node 30 (wrist_3_joint)" in out and "node 8 " not in out


def test_unknown_arm_is_one_clear_line(tmp_path, capsys):
    assert _run(["bus", "selftest", "--robot", "ur7"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "mrguide bus selftest: unknown robot 'ur7'; known robots: ur10, ur5 (or [robot] file = ...)"
