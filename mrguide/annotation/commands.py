"""`mrguide train --expert live` options, `mrguide deploy --learn`'s `--annotate`, and `mrguide annotate bot`."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from mrguide.cli_args import nonnegative_float, nonnegative_int, positive_float, positive_int
from mrguide.errors import InputError


class LiveTrainPlugin:
    """The live-session options of `mrguide train` (policies.commands.LivePlugin)."""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        g = parser.add_argument_group("live annotation (--expert live)")
        g.add_argument(
            "--host", default="127.0.0.1", help="address to serve the annotation page on (0.0.0.0: every interface)"
        )
        g.add_argument("--port", type=nonnegative_int, default=8765, help="port (0: any free port)")
        g.add_argument(
            "--cert",
            help="TLS certificate (PEM) for https/wss: a headset's browser needs a secure context off localhost",
        )
        g.add_argument("--key", help="TLS private key (PEM)")
        g.add_argument("--token", help="access token in the page URL (default: a new random token)")
        g.add_argument(
            "--on-timeout",
            choices=("wait", "skip", "oracle"),
            default="wait",
            help="when nobody answers: pause training (wait), drop the demonstration (skip), or let the "
            "scripted oracle answer, tagged and not counted as human input (oracle)",
        )
        g.add_argument(
            "--annotation-timeout",
            type=positive_float,
            default=30.0,
            metavar="S",
            help="seconds a request waits under --on-timeout skip|oracle",
        )
        g.add_argument(
            "--claim-timeout",
            type=positive_float,
            default=60.0,
            metavar="S",
            help="a client that claimed a request and sends nothing for this long loses the claim",
        )
        g.add_argument(
            "--registration", help="calibration JSON of `mrguide calibrate`: places the scene in the headset"
        )

    def open_session(self, args: argparse.Namespace, on_waiting: Callable[[bool], None]):
        from mrguide.annotation.live import LiveOptions, LiveSession

        options = LiveOptions(
            args.host,
            args.port,
            args.cert,
            args.key,
            args.token,
            args.on_timeout,
            args.annotation_timeout,
            args.claim_timeout,
            args.registration,
        )
        return LiveSession(options, on_waiting)


def host_port(text: str) -> tuple[str, int]:
    """`[HOST:]PORT` (an IPv6 host in brackets) → (host, port); the host defaults to 127.0.0.1."""
    host, sep, port = text.rpartition(":")
    host = host.strip("[]") if sep else "127.0.0.1"
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not host or not 0 <= number <= 65535:
        raise argparse.ArgumentTypeError(
            f"expected [HOST:]PORT with a port in 0..65535 (0: any free port), got {text!r}"
        )
    return host, number


class CellAnnotatePlugin:
    """The annotation page of `mrguide deploy --learn` (deploy.commands.AnnotationPlugin): a person steps in."""

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        g = parser.add_argument_group("a person stepping in while the cell learns (--learn)")
        g.add_argument(
            "--annotate",
            type=host_port,
            metavar="[HOST:]PORT",
            help="serve the annotation page (default host 127.0.0.1; 0.0.0.0: every interface): Intervene takes over "
            "the next episode, played by the expert of the person's pick and place marks and stored as expert data",
        )
        g.add_argument("--cert", help="TLS certificate (PEM) for https/wss, as for `mrguide train --expert live`")
        g.add_argument("--key", help="TLS private key (PEM)")
        g.add_argument("--token", help="access token in the page URL (default: a new random token)")
        g.add_argument(
            "--annotation-timeout",
            type=positive_float,
            default=30.0,
            metavar="S",
            help="seconds the arm waits at an episode's start for each mark; then the policy plays the episode",
        )

    def open(self, args: argparse.Namespace, learner: Any, seed: int) -> Any:
        """The page and broker of `--annotate` for `learner` (a CellLearner), or None without it; InputError when
        the cell does not learn."""
        if args.annotate is None:
            return None
        if learner is None:
            raise InputError("--annotate needs --learn RUN_DIR: a person's intervention is expert data for a learner")
        from mrguide.annotation.cell_interventions import CellInterventions
        from mrguide.annotation.live import LiveOptions

        host, port = args.annotate
        options = LiveOptions(host, port, args.cert, args.key, args.token, "skip", args.annotation_timeout)
        return CellInterventions(options, learner.spec, learner.task, learner.guidance, learner.out, seed)


def add_annotate_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("annotate", help="live annotation clients")
    asub = p.add_subparsers(dest="annotate_command", required=True)
    b = asub.add_parser("bot", help="a scripted client that answers annotation requests like the simulated annotator")
    b.add_argument("--url", required=True, help="the annotation page URL printed by `mrguide train --expert live`")
    b.add_argument(
        "--noise",
        type=nonnegative_float,
        metavar="SIGMA",
        help="std of an isotropic marking error per axis, m (default 0, or the --config's)",
    )
    b.add_argument(
        "--config",
        help="a training config whose [guidance.noise] is the error model to mark with, e.g. "
        "configs/runs/person.toml (a person in a headset: bias, line-of-sight error, slips)",
    )
    b.add_argument("--seed", type=nonnegative_int, default=0, help="training seed whose simulated annotator to mimic")
    b.add_argument("--delay", type=nonnegative_float, default=0.0, metavar="S", help="think time before each answer, s")
    b.add_argument("--count", type=positive_int, help="stop after this many answers")
    b.add_argument("--insecure", action="store_true", help="accept a self-signed TLS certificate")
    b.add_argument(
        "--intervene",
        action="store_true",
        help="step in once on connecting, as the page's Intervene button (the next episode is demonstrated)",
    )
    b.set_defaults(func=cmd_annotate_bot)


def cmd_annotate_bot(args: argparse.Namespace) -> int:
    import dataclasses

    from mrguide.annotation.bot import AnnotationBot, BotError, BotOptions
    from mrguide.config import load_section
    from mrguide.policies.guidance import GuidanceConfig

    noise = load_section(GuidanceConfig, args.config, "guidance").noise  # ConfigError: exit 2 with the reason
    if args.noise is not None:
        noise = dataclasses.replace(noise, sigma=args.noise)
    try:
        bot = AnnotationBot(
            BotOptions(args.url, noise, args.seed, args.delay, args.count, args.insecure, args.intervene)
        )
        print(f"annotation bot: connecting to {bot.url.split('?')[0]}", file=sys.stderr)
        report = bot.run()
    except BotError as exc:
        print(f"mrguide annotate bot: {exc}", file=sys.stderr)
        return 2
    lat = sorted(report.latencies_s or [0.0])
    print(
        f"annotation bot: {report.answers} answers, {report.refused} refused; "
        f"median think time {1e3 * lat[len(lat) // 2]:.2f} ms"
    )
    return 0
