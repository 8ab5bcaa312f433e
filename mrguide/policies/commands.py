"""`mrguide train` and `mrguide experiment`: argument parsing and progress display for the policies package."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections import deque
from pathlib import Path

from tqdm import tqdm


def add_train_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train DDPG in the twin, with or without MR-style expert guidance")
    p.add_argument("--config", help="TOML config ([train], [ddpg], [guidance], [robot], [twin], [task])")
    p.add_argument("--out", default="runs/train", help="run directory: checkpoint, metrics, annotations, policy")
    p.add_argument("--steps", type=int, help="override train.total_steps")
    p.add_argument("--seed", type=int, help="override train.seed")
    p.add_argument("--stop-after", type=int, metavar="N",
                   help="stop (checkpoint, export) after N steps, keeping the schedule of total_steps; --resume continues")
    p.add_argument("--no-guidance", action="store_true", help="baseline DDPG (guidance.enabled = false)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_train)


def cmd_train(args: argparse.Namespace) -> int:
    from mrguide.policies.export import export_actor
    from mrguide.policies.train import CheckpointError, Trainer, load_train_config

    tc, dc, gc, ec = load_train_config(args.config)
    if args.steps is not None:
        tc = dataclasses.replace(tc, total_steps=args.steps)
    if args.seed is not None:
        tc = dataclasses.replace(tc, seed=args.seed)
    if args.no_guidance:
        gc = dataclasses.replace(gc, enabled=False)
    out = Path(args.out)
    if not args.resume and (out / "checkpoint.pt").exists():
        print(f"mrguide train: {out} already holds a run; use --resume or another --out")
        return 2
    tr = Trainer(tc, dc, gc, ec, out)
    try:
        if args.resume:
            try:
                tr.load_checkpoint()
            except CheckpointError as exc:
                print(f"mrguide train: {exc}")
                return 2
        recent: deque[int] = deque(maxlen=20)
        with tqdm(total=min(tc.total_steps, args.stop_after or tc.total_steps), initial=tr.step, desc="train", unit="step", disable=args.quiet) as bar:
            def progress(row: dict) -> None:
                recent.append(row["success"])
                bar.update(row["step"] - bar.n)
                bar.set_postfix(ret=f"{row['return']:.1f}", succ20=f"{sum(recent) / len(recent):.0%}",
                                lam=f"{row['lambda']:.2f}", interv=tr.interventions, asked=row["asked"])

            tr.run(progress, stop_at=args.stop_after)
        final = tr.last_eval or tr.evaluate()
        policy = export_actor(tr.agent.actor, out / "policy.npz", tr.env.workspace, tr.env.task_cfg, tr.env.twin_cfg.decision_period,
                              {"trained": {"steps": tr.step, "seed": tc.seed, "guidance": gc.enabled}})
    finally:
        tr.close()
    print(f"trained {tr.step} steps in {tr.wall_s():.0f} s ({tr.step / max(tr.wall_s(), 1e-9):.0f} steps/s); "
          f"expert interventions {tr.interventions}, annotations asked {tr.cache.asked} / reused {tr.cache.reused}")
    print(f"deterministic evaluation: {final['success_rate']:.0%} success over {tc.eval_episodes} episodes")
    print(f"policy: {policy}   metrics: {out / 'metrics.csv'}   checkpoint: {out / 'checkpoint.pt'}")
    return 0


def add_experiment_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("experiment", help="the paper's experiments")
    p.add_argument("name", choices=["learning-curves"], help="learning-curves: baseline vs guided DDPG (Fig. 3, 5, 9)")
    p.add_argument("--config", help="TOML config for every run")
    p.add_argument("--out", default="runs/learning-curves")
    p.add_argument("--seeds", type=int, default=10)
    p.add_argument("--steps", type=int, default=20_000)
    p.add_argument("--workers", type=int, default=2, help="parallel worker processes")
    p.add_argument("--variants", default="baseline,guided", help="comma-separated subset of baseline,guided")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_experiment)


def cmd_experiment(args: argparse.Namespace) -> int:
    from mrguide.policies.experiments import VARIANTS, run_learning_curves

    variants = tuple(v for v in VARIANTS if v in args.variants.split(","))
    unknown = set(args.variants.split(",")) - set(VARIANTS)
    if unknown or not variants:
        print(f"mrguide experiment: --variants must name some of {', '.join(VARIANTS)}, got {args.variants!r}", file=sys.stderr)
        return 2
    md = run_learning_curves(Path(args.out), args.seeds, args.steps, args.workers, args.config, not args.quiet, variants)
    print(md.read_text())
    print(f"figures and CSVs in {args.out}")
    return 0
