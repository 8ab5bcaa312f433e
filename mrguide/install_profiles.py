"""The install profiles (pyproject.toml's extras) and the one line a command says when its profile is missing.

    pip install 'mrguide[robot]'   robot PC: deploy, bus, calibrate --images, camera check (no torch, PyBullet, Ray)
    pip install 'mrguide[train]'   workstation: the robot profile plus the twin, training, experiments, annotation
    pip install 'mrguide[replay]'  mrguide replay (Rerun) and mrguide export lerobot (parquet), beside either

The bare `pip install mrguide` gets only what the `mrguide` command needs to build its parser and print help.
Every command imports its packages inside its handler, so a missing one surfaces as ModuleNotFoundError
while the command runs; `mrguide.cli.main` turns that into `missing_profile_message` and exit 2.
Standard library only.
"""

from __future__ import annotations

#: extra -> what the message calls it
PROFILES = {"robot": "robot", "train": "workstation", "replay": "replay"}

#: top-level module -> (the distribution that provides it, the extra that lists it)
MODULES = {
    "can": ("python-can", "robot"),
    "canopen": ("canopen", "robot"),
    "cv2": ("opencv-python-headless", "robot"),
    "pinocchio": ("pin", "robot"),
    "ruckig": ("ruckig", "robot"),
    "torch": ("torch", "train"),
    "pybullet": ("pybullet", "train"),
    "pybullet_data": ("pybullet", "train"),
    "gymnasium": ("gymnasium", "train"),
    "ray": ("ray", "train"),
    "matplotlib": ("matplotlib", "train"),
    "scipy": ("scipy", "train"),
    "aiohttp": ("aiohttp", "train"),
    "rerun": ("rerun-sdk", "replay"),
    "pyarrow": ("pyarrow", "replay"),
}


def missing_profile_message(command: str, exc: ModuleNotFoundError) -> str | None:
    """The line for `command` (e.g. "mrguide train") that could not import `exc.name`, such as
    mrguide train needs the workstation install: pip install 'mrguide[train]' (missing: torch)
    or None when the module is none of those the profiles provide (a broken install: the traceback says more).
    """
    top = (exc.name or "").split(".")[0]
    if top not in MODULES:
        return None
    distribution, extra = MODULES[top]
    return f"{command} needs the {PROFILES[extra]} install: pip install 'mrguide[{extra}]' (missing: {distribution})"
