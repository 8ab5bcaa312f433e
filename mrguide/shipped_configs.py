"""Where the configuration files shipped with mrguide are: the checkout's `configs/` (an editable install,
CI, a clone), or the copy that a plain `pip install .` puts under `<prefix>/share/mrguide/configs`.

`configs/` is split by kind: `runs/` (training run configs), `cells/` (the cells deploy and sim-to-real run
in), `devices/` (the CAN bus description, the marker calibration config, a camera calibration file) and
`experiments/` (`mrguide experiment` files)."""

from __future__ import annotations

import sysconfig
from pathlib import Path

from mrguide.config import ConfigError

CHECKOUT = Path(__file__).resolve().parents[1] / "configs"
INSTALLED = Path(sysconfig.get_paths()["data"]) / "share" / "mrguide" / "configs"


def shipped_config(*parts: str) -> Path:
    """The shipped file `configs/<parts...>`, from the checkout if there is one, else from the installed copy."""
    for root in (CHECKOUT, INSTALLED):
        path = root.joinpath(*parts)
        if path.is_file():
            return path
    raise ConfigError(
        f"the shipped config {'/'.join(parts)} is missing (looked in {CHECKOUT} and {INSTALLED}); "
        "reinstall mrguide or give the file explicitly"
    )
