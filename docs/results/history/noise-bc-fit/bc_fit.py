"""Does behaviour cloning average label noise out of the grasp target? (Fig. 7 diagnosis, offline.)

Fits the actor (the training's architecture and learning rate) by behaviour cloning alone — no critic — on
the expert states of a noise-free guided run, with labels = the scripted expert's action plus fresh Gaussian
noise of σ per axis on every stored transition (the `stored` reading; unclipped, or clipped to the action box
as `guidance.action_noise_clip = true` does), and measures the fitted actor's grasp target against the
expert's on the expert states of another run (held out): median x/y error per axis and the median height
above the expert's target, over every grasp-phase state. Then runs the fitted actor on its own (closed loop,
deterministic) for 30 episodes of the training twin and counts the outcomes: a fit that is precise on the
expert's states can still drift once the arm strays off them. Both for the actor after the last update and
for the Polyak average of its weights over the fit (τ = 0.005, what `ddpg.act_with_target` evaluates).

    python docs/results/noise-bc-fit/bc_fit.py > docs/results/noise-bc-fit/bc_fit.txt

Inputs: `expert_states.npz` here, the expert pools' states of seeds 0 and 1 of the σ = 0 runs of
docs/results/noise-robustness (from their checkpoints, not committed; the runs are re-created by
`mrguide experiment noise-robustness --seeds 2` with sigmas = [0.0]); the noise-free expert visited them.
"""
import copy
from pathlib import Path

import numpy as np
import torch

from mrguide.policies.ddpg import Actor, ObsScaler, obs_scaling
from mrguide.task import oracle_action, phase_from_progress
from mrguide.twin.env import PickPlaceEnv
from mrguide.twin.rollout import run_episodes

STATES = Path(__file__).resolve().parent / "expert_states.npz"
UPDATES = 20_000  # one per training step of a 20k-step run
TAU = 0.005  # DDPG's soft target update rate
BATCH = 64  # about the expert share of a 256-sample batch over a guided run
SIGMAS = (0.0, 0.02, 0.05, 0.07)
EPISODES = 30
HEADS = ("absolute", "phase_anchor", "anchor_offset")


def expert_states(seed: int) -> np.ndarray:
    with np.load(STATES) as states:
        return states[f"seed{seed}"]


def fit(obs: np.ndarray, labels: np.ndarray, head: str, offset, scale, seed: int) -> tuple[Actor, Actor]:
    """The actor after UPDATES steps of cloning, and the Polyak average of its weights (τ = TAU, as DDPG's
    target actor)."""
    torch.manual_seed(seed)
    actor = Actor(ObsScaler(offset, scale), 4, (96, 96), head)
    averaged = copy.deepcopy(actor)
    opt = torch.optim.Adam(actor.parameters(), lr=5e-4)
    rng = np.random.default_rng(seed)
    o, a = torch.as_tensor(obs), torch.as_tensor(labels)
    for _ in range(UPDATES):
        i = torch.as_tensor(rng.integers(0, len(obs), BATCH))
        loss = ((actor(o[i]) - a[i]) ** 2).sum(-1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        with torch.no_grad():
            for p, q in zip(actor.parameters(), averaged.parameters()):
                q.lerp_(p, TAU)
    return actor, averaged


def grasp_error(actor: Actor, states: np.ndarray, truth: np.ndarray, ws) -> str:
    """Median x/y error per axis, its p90, the share within 13 mm on both axes and the median height error."""
    with torch.no_grad():
        pred = actor(torch.as_tensor(states)).numpy()
    err_mm = (np.array([ws.to_cartesian(p[:3]) for p in pred]) - truth) * 1000
    xy, dz = np.abs(err_mm[:, :2]), err_mm[:, 2]
    return (f"grasp x/y error median {np.median(xy):4.1f} mm, p90 {np.percentile(xy, 90):4.1f} mm, both within 13 mm "
            f"{np.mean(xy.max(1) < 13):4.0%}, height above the mark median {np.median(dz):5.1f} mm")


def closed_loop(actor: Actor, env: PickPlaceEnv) -> str:
    """The outcomes of EPISODES deterministic episodes of `actor` alone, e.g. "success 28, no_grasp 2"."""

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return actor(torch.as_tensor(obs, dtype=torch.float32)).numpy()

    counts = run_episodes(env, act, range(5_000_000, 5_000_000 + EPISODES)).outcomes()
    return ", ".join(f"{k} {v}" for k, v in counts.most_common())


def main() -> None:
    torch.set_num_threads(1)
    env = PickPlaceEnv()
    ws, task = env.workspace, env.task_cfg
    offset, scale = obs_scaling(ws)
    train, test = expert_states(0), expert_states(1)
    clean = np.array([oracle_action(s, task, ws.to_normalized) for s in train], dtype=np.float32)
    grasp = np.array([phase_from_progress(s[4]) == 1 for s in test])
    test_g = test[grasp]
    truth = np.array([ws.to_cartesian(oracle_action(s, task, ws.to_normalized)[:3]) for s in test_g])
    print(f"train: {len(train)} expert states (seed 0), {sum(phase_from_progress(s[4]) == 1 for s in train)} in the grasp phase; "
          f"test: {len(test)} (seed 1), {len(test_g)} in the grasp phase; {UPDATES} updates of {BATCH}")
    for head in HEADS:
        for clip in (False, True):
            for sigma in SIGMAS:
                if sigma == 0 and clip:
                    continue
                rng = np.random.default_rng(104_729)
                labels = clean.copy()
                for k in range(len(train)):
                    target = ws.to_cartesian(clean[k, :3]) + rng.normal(0.0, sigma, 3)
                    labels[k, :3] = ws.to_normalized(target)
                if clip:
                    labels[:, :3] = np.clip(labels[:, :3], -1.0, 1.0)
                actor, averaged = fit(train, labels, head, offset, scale, seed=0)
                print(f"{head:13s} clip={str(clip):5s} sigma={sigma:.2f} m", flush=True)
                for name, net in (("final", actor), ("averaged", averaged)):
                    print(f"    {name:8s}: {grasp_error(net, test_g, truth, ws)}; closed loop: {closed_loop(net, env)}", flush=True)
    env.close()


if __name__ == "__main__":
    main()
