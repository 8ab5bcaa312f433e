"""[safety]: refused at load unless finite and in range, and every check fails closed on NaN.

NaN or inf in [safety] used to switch checks off: a NaN tolerance let a setpoint at 100 x v_max pass, a
NaN following-error limit never fired, a NaN stall time-out busy-spun the watchdog and an infinite one
killed its thread (the run went on unsupervised).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mrguide.config import ConfigError, load_optional_section
from mrguide.deploy import runtime as runtime_module
from mrguide.deploy.safety import SafetyConfig, Supervisor, Watchdog
from mrguide.robot import load_robot

KEYS = ("following_error", "stall_timeout", "limit_tolerance", "max_consecutive_ik_failures")


@pytest.mark.parametrize("key", KEYS)
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "-1", "1e6"])
def test_bad_safety_values_are_refused_at_load_naming_file_section_and_key(tmp_path, key, value):
    path = tmp_path / "deploy.toml"
    path.write_text(f"[safety]\n{key} = {value}\n")
    with pytest.raises(ConfigError) as info:
        load_optional_section(SafetyConfig, path, "safety")
    message = str(info.value)
    assert str(path) in message and "[safety]" in message and key in message


def test_the_defaults_and_the_dry_run_values_are_accepted():
    assert SafetyConfig() == SafetyConfig(
        following_error=0.05, max_consecutive_ik_failures=3, stall_timeout=0.25, limit_tolerance=1e-6
    )
    SafetyConfig(following_error=0.1)


def _unchecked(**values) -> SimpleNamespace:
    """Limits that bypass the load-time validation, to test that the checks themselves fail closed."""
    defaults = dict(following_error=0.05, max_consecutive_ik_failures=3, stall_timeout=0.25, limit_tolerance=1e-6)
    return SimpleNamespace(**{**defaults, **values})


def test_setpoint_check_trips_when_its_tolerance_is_nan():
    spec = load_robot()
    supervisor = Supervisor(spec, _unchecked(limit_tolerance=math.nan))
    assert supervisor.check_setpoint(spec.q_home, 100 * spec.v_max, np.zeros(6)) is not None
    assert supervisor.check_setpoint(spec.q_home, np.zeros(6), 100 * spec.a_max) is not None


@pytest.mark.parametrize("limit, error", [(math.nan, 0.0), (0.05, math.nan), (0.05, 0.06)])
def test_following_check_trips_on_nan(limit, error):
    supervisor = Supervisor(load_robot(), _unchecked(following_error=limit))
    assert supervisor.check_following(error) is not None


def test_following_check_passes_within_the_limit():
    assert Supervisor(load_robot(), SafetyConfig()).check_following(0.01) is None


@pytest.mark.parametrize("timeout", [math.nan, math.inf, 0.0, -1.0])
def test_watchdog_refuses_a_timeout_it_cannot_keep(timeout):
    with pytest.raises(ValueError, match="stall"):
        Watchdog(timeout, lambda age: None)


def test_a_dead_watchdog_thread_stops_the_run(run_dry, monkeypatch):
    monkeypatch.setattr(runtime_module.Watchdog, "_run", lambda self: None)  # the thread ends at once
    summary, _, _ = run_dry()
    assert summary.stopped is not None and "watchdog" in summary.stopped
