"""`mrguide config show`: the effective configuration of a training run, every section, as JSON."""

from __future__ import annotations

import argparse
import json

from mrguide.cli_args import override_arg
from mrguide.policies.choices import OVERRIDE_SECTIONS


def add_config_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("config", help="the effective configuration of a training run")
    csub = p.add_subparsers(dest="config_command", required=True)
    show = csub.add_parser(
        "show",
        help="print every section (" + ", ".join(OVERRIDE_SECTIONS) + ") as JSON: the defaults, then --config's "
        "values, then --set's",
    )
    show.add_argument("--config", help="TOML config, as `mrguide train --config` takes it")
    show.add_argument(
        "--set",
        type=override_arg,
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="as `mrguide train --set`; repeatable",
    )
    show.set_defaults(func=cmd_config_show)


def cmd_config_show(args: argparse.Namespace) -> int:
    from mrguide.config import to_dict
    from mrguide.policies.train_config import apply_overrides, load_sac_config, load_train_config

    tc, dc, gc, ec, sc = apply_overrides(
        (*load_train_config(args.config), load_sac_config(args.config)), dict(args.set), "--set"
    )
    sections = {"train": to_dict(tc), "ddpg": to_dict(dc), "sac": to_dict(sc), "guidance": to_dict(gc), **to_dict(ec)}
    print(json.dumps(sections, indent=1))
    return 0
