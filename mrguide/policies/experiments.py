"""`mrguide experiment learning-curves`: baseline vs guided DDPG over seeds (paper Fig. 3, 5, 9).

Seeds run in parallel worker processes; each writes its own run directory, so an interrupted
experiment can be re-run and only missing runs are trained again. Aggregation reads the CSVs only.
"""

from __future__ import annotations

import csv
import dataclasses
import multiprocessing as mp
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

#: Convergence: the deterministic-evaluation success rate over the last 20 evaluation episodes reaches
#: this and stays at or above it at every later evaluation (paper Sec. V-C: "stays above the task threshold").
CONVERGENCE_THRESHOLD = 0.8
WINDOW_EPISODES = 20
VARIANTS = ("baseline", "guided")


@dataclass(frozen=True)
class RunSpec:
    variant: str
    seed: int
    steps: int
    config: str | None
    out: str


def _train_one(spec: RunSpec, queue) -> str:
    """Worker: one seed of one variant, resumed if a checkpoint exists, finished if done already."""
    from mrguide.policies.train import Trainer, load_train_config

    out = Path(spec.out)
    if (out / "done").exists():
        return spec.out
    tc, dc, gc, ec = load_train_config(spec.config)
    tc = dataclasses.replace(tc, total_steps=spec.steps, seed=spec.seed)
    gc = dataclasses.replace(gc, enabled=spec.variant == "guided")
    tr = Trainer(tc, dc, gc, ec, out)
    try:
        if (out / "checkpoint.pt").exists():
            tr.load_checkpoint()
        last = [tr.step]

        def progress(row: dict) -> None:
            queue.put(row["step"] - last[0])
            last[0] = row["step"]

        tr.run(progress)
        (out / "done").write_text(f"{tr.wall_s():.1f}\n{tr.update_ms():.3f}\n")
    finally:
        tr.close()
    return spec.out


def run_learning_curves(out: Path, seeds: int, steps: int, workers: int, config: str | None, show_progress: bool = True,
                        variants: tuple[str, ...] = VARIANTS) -> Path:
    """Train every (variant, seed) in parallel, then write PNGs, CSVs and a markdown table into `out`."""
    from tqdm import tqdm

    specs = [RunSpec(v, s, steps, config, str(out / v / f"seed{s}")) for v in variants for s in range(seeds)]
    ctx = mp.get_context("spawn")
    with ctx.Manager() as manager:
        queue = manager.Queue()
        with ctx.Pool(workers) as pool, tqdm(total=steps * len(specs), unit="step", desc="learning curves", disable=not show_progress) as bar:
            pending = [pool.apply_async(_train_one, (spec, queue)) for spec in specs]
            while pending:
                while not queue.empty():
                    bar.update(queue.get())
                done = [p for p in pending if p.ready()]
                for p in done:
                    p.get()  # re-raise a worker's error here
                    pending.remove(p)
                time.sleep(0.2)
    from mrguide.policies.train import load_train_config

    return summarize(out, seeds, steps, load_train_config(config)[0].eval_episodes, variants=variants)


# -- aggregation ---------------------------------------------------------------------------------

def _read(path: Path) -> list[dict]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def convergence_step(eval_rows: list[dict], episodes_per_eval: int) -> int | None:
    """First evaluation step from which the moving success over the last 20 eval episodes stays ≥ threshold."""
    k = max(1, -(-WINDOW_EPISODES // episodes_per_eval))
    rates = [float(r["success_rate"]) for r in eval_rows]
    moving = [float(np.mean(rates[i - k + 1: i + 1])) for i in range(k - 1, len(rates))]
    for i in range(len(moving)):
        if min(moving[i:]) >= CONVERGENCE_THRESHOLD:
            return int(eval_rows[i + k - 1]["step"])
    return None


def _ci95(x: np.ndarray) -> np.ndarray:
    """Half-width of the 95 % confidence interval of the mean over axis 0 (Student t)."""
    n = x.shape[0]
    return stats.t.ppf(0.975, n - 1) * x.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(x.shape[1])


def summarize(out: Path, seeds: int, steps: int, eval_episodes: int, grid_step: int = 1000,
              variants: tuple[str, ...] = VARIANTS) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid_step = min(grid_step, steps)
    grid = np.arange(grid_step, steps + 1, grid_step)
    curves, conv, asked_curves, ratio_curves, table, per_run = {}, {}, {}, {}, [], []
    for v in variants:
        returns, conv_steps, asked_at_conv, asked_c, ratio_c, finals, walls = [], [], [], [], [], [], []
        for s in range(seeds):
            run = out / v / f"seed{s}"
            rows = _read(run / "metrics.csv")
            ev = _read(run / "eval.csv")
            # Fig. 3 uses the deterministic evaluation returns: training episodes of the guided runs are cut
            # short when the expert takes over, so their returns are not comparable with the baseline's
            ev_st = np.array([int(r["step"]) for r in ev])
            ev_ret = np.array([float(r["mean_return"]) for r in ev])
            series = [float(ev_ret[ev_st <= g + grid_step // 2][-1]) if (ev_st <= g + grid_step // 2).any() else np.nan for g in grid]
            returns.append(series)
            all_st = np.array([int(r["step"]) for r in rows])
            asked = np.array([int(r["asked"]) for r in rows])
            ratio = np.array([float(r["expert_ratio"]) for r in rows])
            asked_c.append([asked[all_st <= g].max() if (all_st <= g).any() else 0 for g in grid])
            ratio_c.append([ratio[(all_st > g - grid_step) & (all_st <= g)].mean() if ((all_st > g - grid_step) & (all_st <= g)).any() else np.nan for g in grid])
            c = convergence_step(ev, eval_episodes)
            conv_steps.append(c)
            asked_at_conv.append(int(asked[all_st <= c].max()) if c is not None and (all_st <= c).any() else None)
            finals.append(float(ev[-1]["success_rate"]))
            done = (run / "done").read_text().split()
            walls.append(float(done[0]))
            per_run.append({"variant": v, "seed": s, "convergence_step": c, "annotations_until_convergence": asked_at_conv[-1],
                            "annotations_total": int(asked.max(initial=0)), "final_eval_success": finals[-1], "wall_s": walls[-1]})
        curves[v], conv[v] = np.array(returns), conv_steps
        asked_curves[v], ratio_curves[v] = np.array(asked_c, float), np.array(ratio_c, float)
        ok = [c for c in conv_steps if c is not None]
        table.append({
            "variant": v, "seeds": seeds,
            "converged_by_5k": sum(c <= 5000 for c in ok), "converged_by_end": len(ok),
            "median_convergence_step": int(np.median(ok)) if ok else None,
            "final_eval_success": float(np.mean(finals)),
            "annotations_until_convergence_median": int(np.median([a for a in asked_at_conv if a is not None])) if any(a is not None for a in asked_at_conv) else None,
            "annotations_until_convergence_max": max((a for a in asked_at_conv if a is not None), default=None),
            "annotations_total_mean": float(asked_curves[v][:, -1].mean()),
            "wall_s_per_run_median": float(np.median(walls)),
        })

    # Fig. 3: mean episode return with 95 % CI
    fig, ax = plt.subplots(figsize=(7, 4))
    colors = {"baseline": "tab:blue", "guided": "tab:red"}
    for v in variants:
        color = colors[v]
        m, h = np.nanmean(curves[v], 0), _ci95(curves[v])
        ax.plot(grid, m, color=color, label=f"{v} DDPG")
        ax.fill_between(grid, m - h, m + h, color=color, alpha=0.2)
    ax.set(xlabel="training step", ylabel="mean return, deterministic evaluation", title=f"Learning curves, {seeds} seeds, 95 % CI")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "fig3_learning_curves.png", dpi=120)
    plt.close(fig)

    # Fig. 5: convergence probability over normalized progress
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.linspace(0, 1, 101)
    for v in variants:
        color = colors[v]
        cs = [c / steps if c is not None else np.inf for c in conv[v]]
        ax.step(x, [np.mean([c <= xi for c in cs]) for xi in x], color=color, where="post", label=f"{v} DDPG")
    ax.set(xlabel="normalized training progress", ylabel="convergence probability", ylim=(-0.02, 1.02),
           title=f"Convergence (eval success over last {WINDOW_EPISODES} episodes ≥ {CONVERGENCE_THRESHOLD:.0%} to the end)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "fig5_convergence.png", dpi=120)
    plt.close(fig)

    if "guided" in variants:
        _plot_expert_effort(out, grid, asked_curves["guided"], ratio_curves["guided"])
    _write_tables(out, seeds, steps, variants, grid, curves, asked_curves, ratio_curves, table, per_run)
    return out / "summary.md"


def _plot_expert_effort(out: Path, grid: np.ndarray, a: np.ndarray, r: np.ndarray) -> None:
    """Fig. 9: expert effort and realized expert ratio of the guided runs."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(grid, a.mean(0), color="tab:red", label="cumulative annotations asked")
    ax.fill_between(grid, a.min(0), a.max(0), color="tab:red", alpha=0.2)
    ax.set(xlabel="training step", ylabel="annotations asked (cumulative)")
    ax2 = ax.twinx()
    ax2.plot(grid, np.nanmean(r, 0), color="tab:green", label="realized expert ratio per batch")
    ax2.fill_between(grid, np.nanmin(r, 0), np.nanmax(r, 0), color="tab:green", alpha=0.2)
    ax2.set(ylabel="expert ratio per batch", ylim=(0, 1))
    handles = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
    ax.legend(handles, [h.get_label() for h in handles], loc="center right")
    fig.tight_layout()
    fig.savefig(out / "fig9_expert_effort.png", dpi=120)
    plt.close(fig)


def _write_tables(out: Path, seeds: int, steps: int, variants: tuple[str, ...], grid: np.ndarray, curves: dict,
                  asked_curves: dict, ratio_curves: dict, table: list[dict], per_run: list[dict]) -> None:
    """curves.csv, summary.csv, runs.csv and summary.md."""
    guided = "guided" in variants
    with (out / "curves.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["step"] + [f"{v}_return_mean" for v in variants] + [f"{v}_return_ci95" for v in variants]
                   + (["guided_asked_mean", "guided_expert_ratio_mean"] if guided else []))
        cis = {v: _ci95(curves[v]) for v in variants}
        for i, g in enumerate(grid):
            extra = ([round(asked_curves["guided"][:, i].mean(), 1), round(float(np.nanmean(ratio_curves["guided"][:, i])), 3)]
                     if guided else [])
            w.writerow([g] + [round(curves[v][:, i].mean(), 3) for v in variants] + [round(cis[v][i], 3) for v in variants]
                       + extra)
    with (out / "summary.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, list(table[0]))
        w.writeheader()
        w.writerows(table)
    with (out / "runs.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, list(per_run[0]))
        w.writeheader()
        w.writerows(per_run)
    md = out / "summary.md"
    lines = [
        f"Learning curves: {seeds} seeds × {steps} steps per variant. Convergence = evaluation success over the "
        f"last {WINDOW_EPISODES} deterministic episodes ≥ {CONVERGENCE_THRESHOLD:.0%} and staying there to the end.",
        "",
        "| variant | converged ≤ 5k steps | converged by the end | median convergence step | final eval success | annotations until convergence (median / max) | annotations in total (mean) | wall time per run (median) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for t in table:
        lines.append(
            f"| {t['variant']} | {t['converged_by_5k']}/{seeds} | {t['converged_by_end']}/{seeds} | {t['median_convergence_step'] or '—'} | "
            f"{t['final_eval_success']:.0%} | {t['annotations_until_convergence_median'] or '—'} / {t['annotations_until_convergence_max'] or '—'} | "
            f"{t['annotations_total_mean']:.0f} | {t['wall_s_per_run_median']:.0f} s |"
        )
    md.write_text("\n".join(lines) + "\n")
