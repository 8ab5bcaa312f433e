"""timing.switch_interval: Python's thread switch interval while the control thread runs, restored after."""

from __future__ import annotations

import sys

import pytest

from mrguide.config import ConfigError
from mrguide.drivers.config import TimingConfig
from mrguide.drivers.realtime import hold_switch_interval, release_switch_interval


def test_the_control_thread_holds_the_configured_interval_until_it_stops(make_rig):
    before = sys.getswitchinterval()
    rig = make_rig(switch_interval=0.0005)
    assert sys.getswitchinterval() == pytest.approx(0.0005)
    rig.cobot.disconnect()
    assert sys.getswitchinterval() == pytest.approx(before)


def test_zero_leaves_the_interpreters_interval(make_rig):
    before = sys.getswitchinterval()
    rig = make_rig(switch_interval=0.0)
    assert sys.getswitchinterval() == before
    rig.cobot.disconnect()
    assert sys.getswitchinterval() == before


def test_holders_nest_and_the_shortest_wins():
    before = sys.getswitchinterval()
    hold_switch_interval(0.002)
    hold_switch_interval(0.0005)
    assert sys.getswitchinterval() == pytest.approx(0.0005)
    release_switch_interval(0.0005)
    assert sys.getswitchinterval() == pytest.approx(0.002)
    release_switch_interval(0.002)
    assert sys.getswitchinterval() == pytest.approx(before)


@pytest.mark.parametrize("bad", [-0.001, 0.01, float("nan")])
def test_an_interval_outside_0_to_5_ms_is_refused(bad):
    with pytest.raises(ConfigError, match="switch_interval"):
        TimingConfig(switch_interval=bad)
