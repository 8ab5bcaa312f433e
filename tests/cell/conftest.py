"""The cell's tests use the deploy tests' dry-run fixture and the driver tests' bus config and arm (imported here so
that pytest finds them for this folder too)."""

from tests.deploy.conftest import run_dry
from tests.drivers.conftest import make_config, robot

__all__ = ["make_config", "robot", "run_dry"]
