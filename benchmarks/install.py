"""run.sh's install of the workstation profile: pip against uv, on a fresh venv with cold caches each time.

Run: python benchmarks/install.py [--rounds N]

Each round makes two fresh venvs from this checkout and installs torch into both with pip (as run.sh does: the
machine's pip configuration finds the CPU wheel), then times the rest of `.[train,dev]` in one with
`pip install --no-compile -e` and in the other with `uv pip install -e` (the installer run.sh uses), the order
alternating between rounds; each installer's cache is a fresh temporary directory, as on a fresh machine. It checks
that both venvs hold the same packages at the same versions (uv itself aside). The package index is the network's:
its speed varies by the hour, so compare the two installers within one run (the ratio), not across runs. The last
line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

from mrguide.cli_args import positive_int

ROOT = Path(__file__).resolve().parent.parent
#: What run.sh installs with pip before the rest: torch's CPU build and uv at the dev extra's pin.
FIRST = [
    "torch==2.13.0",
    next(
        r
        for r in tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["dev"]
        if r.startswith("uv")
    ),
]


def fresh_venv(where: Path, cache: Path) -> Path:
    """A venv at `where` with torch and uv installed by pip (not timed); its python."""
    subprocess.run([sys.executable, "-m", "venv", str(where)], check=True)
    python = where / "bin" / "python"
    env = {**os.environ, "PIP_CACHE_DIR": str(cache)}
    subprocess.run([python, "-m", "pip", "install", "-q", "--no-compile", *FIRST], check=True, env=env)
    return python


def timed_install(installer: str, python: Path, cache: Path) -> float:
    """Seconds `installer` ("pip" or "uv") takes to install `.[train,dev]` into the venv of `python`."""
    if installer == "pip":
        cmd = [str(python), "-m", "pip", "install", "-q", "--no-compile", "-e", ".[train,dev]"]
        env = {**os.environ, "PIP_CACHE_DIR": str(cache)}
    else:
        cmd = [str(python.parent / "uv"), "pip", "install", "-q", "--python", str(python), "-e", ".[train,dev]"]
        env = {**os.environ, "UV_CACHE_DIR": str(cache), "UV_LINK_MODE": "copy"}
    start = time.monotonic()
    subprocess.run(cmd, check=True, env=env, cwd=ROOT)
    return time.monotonic() - start


def frozen(python: Path) -> list[str]:
    """`pip freeze` of a venv without uv itself and without this package's editable line."""
    out = subprocess.run([python, "-m", "pip", "freeze"], check=True, capture_output=True, text=True).stdout
    return sorted(line for line in out.splitlines() if not line.startswith(("uv==", "-e ", "# Editable")))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=positive_int, default=1)
    args = parser.parse_args()
    seconds: dict[str, list[float]] = {"pip": [], "uv": []}
    same = True
    for round_ in range(args.rounds):
        order = ["pip", "uv"] if round_ % 2 == 0 else ["uv", "pip"]
        pythons = {}
        with tempfile.TemporaryDirectory() as tmp:
            for installer in order:
                base = Path(tmp) / installer
                python = fresh_venv(base / "venv", base / "pip-cache")
                seconds[installer].append(timed_install(installer, python, base / f"{installer}-cache"))
                pythons[installer] = python
                print(f"round {round_ + 1}: {installer} {seconds[installer][-1]:.0f} s", flush=True)
            same = same and frozen(pythons["pip"]) == frozen(pythons["uv"])
    pip_s, uv_s = statistics.median(seconds["pip"]), statistics.median(seconds["uv"])
    result = {"rounds": args.rounds, "pip_s": round(pip_s, 1), "uv_s": round(uv_s, 1)}
    result |= {"pip_over_uv": round(pip_s / uv_s, 2), "same_packages": same}
    print(json.dumps(result))


if __name__ == "__main__":
    main()
