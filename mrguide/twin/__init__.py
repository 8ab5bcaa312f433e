"""The PyBullet digital twin. Importing this package loads PyBullet (if installed) without its build-time
banner on stderr, so that a command refusing bad input still ends in exactly one line there. The package
itself imports without PyBullet, so the `mrguide` command (whose parser lists the twin's commands) runs on
a robot PC that has none."""

import os


def _import_pybullet_quietly() -> None:
    """Import pybullet with file descriptor 2 pointed at /dev/null (its C code prints the banner)."""
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401  (cached in sys.modules for every later import)
    except ImportError:
        pass  # no PyBullet (the robot PC): the twin's modules that need it say so when they are imported
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


_import_pybullet_quietly()
