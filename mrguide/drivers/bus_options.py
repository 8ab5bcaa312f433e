"""`[bus] options`: only keyword arguments that the chosen python-can interface takes.

python-can hands unknown keyword arguments on to `BusABC`, which ignores them: a misspelt option
(`recieve_own_messages`) would silently do nothing. The accepted keys of an interface are the named
parameters of its bus class, plus those a few classes read from `**kwargs` (python-can 4.x, listed below).
`channel`, `bitrate` (keys of [bus]), `timing` and `can_filters` (objects, not TOML values) are not options.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import logging
import math
from collections.abc import Mapping

from can.interfaces import BACKENDS

from mrguide.config import ConfigError

#: Keys read from `**kwargs` by python-can 4.x bus classes (their docstrings list them).
KWARGS_READ: dict[str, tuple[str, ...]] = {
    "kvaser": (
        "tseg1",
        "tseg2",
        "sjw",
        "no_samp",
        "driver_mode",
        "single_handle",
        "receive_own_messages",
        "exclusive",
        "override_exclusive",
        "accept_virtual",
        "no_init_access",
        "fd",
        "data_bitrate",
        "fd_non_iso",
    ),
    "pcan": (
        "fd",
        "f_clock",
        "f_clock_mhz",
        "nom_brp",
        "nom_tseg1",
        "nom_tseg2",
        "nom_sjw",
        "data_brp",
        "data_tseg1",
        "data_tseg2",
        "data_sjw",
        "auto_reset",
    ),
    "slcan": ("btr",),
}
_NOT_OPTIONS = frozenset({"self", "channel", "bitrate", "timing", "can_filters"})


def check_bus_options(interface: str, options: Mapping[str, object]) -> None:
    """ConfigError naming the key unless every key of `options` is taken by `interface` and every number is finite."""
    for key, value in options.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"bus.options: {key!r} = {value!r}: must be finite")
    if not options:
        return
    accepted = accepted_options(interface)
    unknown = sorted(set(options) - accepted)
    if unknown:
        raise ConfigError(
            f"bus.options: {', '.join(map(repr, unknown))} not taken by python-can's {interface!r} interface; "
            f"it takes: {', '.join(sorted(accepted)) or 'no options'}"
        )


@functools.cache
def accepted_options(interface: str) -> frozenset[str]:
    """The option keys python-can's `interface` takes; ConfigError if its module does not load here."""
    module_name, class_name = BACKENDS[interface]
    can_log = logging.getLogger("can")
    level = can_log.level
    can_log.setLevel(logging.ERROR)  # backends warn on import about missing vendor libraries
    try:
        bus_class = getattr(importlib.import_module(module_name), class_name)
    except Exception as exc:  # a missing vendor package or a Windows-only backend
        raise ConfigError(
            f"bus.options: cannot check options for interface {interface!r}, its python-can backend "
            f"does not load here ({type(exc).__name__}: {exc})"
        ) from exc
    finally:
        can_log.setLevel(level)
    params = inspect.signature(bus_class.__init__).parameters.values()
    named = {p.name for p in params if p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)}
    return frozenset((named | set(KWARGS_READ.get(interface, ()))) - _NOT_OPTIONS)
