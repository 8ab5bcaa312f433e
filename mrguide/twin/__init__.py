"""The PyBullet digital twin. Importing this package loads PyBullet without its build-time banner on
stderr, so that a command refusing bad input still ends in exactly one line there."""

import os


def _import_pybullet_quietly() -> None:
    """Import pybullet with file descriptor 2 pointed at /dev/null (its C code prints the banner)."""
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401  (cached in sys.modules for every later import)
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


_import_pybullet_quietly()
