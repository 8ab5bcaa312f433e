"""Trace Fig. 7's run sigma_0.020/seed0 to step 250 with the current code: each cell measurement of a pick or a place
(its offset from the anchor the demonstration planned at) beside where the twin's part was planned and where it is
when measured. Run from the repository root: python docs/results/withdrawal/trace.py > docs/results/withdrawal/trace.txt
"""

import tempfile

import numpy as np

from mrguide.experiments.train_runs import TrainRun, configs
from mrguide.policies.train import Trainer

OVERRIDES = {"guidance.noise.sigma": 0.02, "guidance.pose.sigma": 0.003, "guidance.pose.bias_sigma": 0.003}
tc, dc, gc, ec = configs(TrainRun("trace", 0, 20_000, True, None, OVERRIDES))[:4]
with tempfile.TemporaryDirectory() as out:
    tr = Trainer(tc, dc, gc, ec, out)
    expert, measured = tr.expert, tr.expert._measured

    def traced(kind: int, point: np.ndarray) -> None:
        at = expert._plan[kind][2]
        part = tr.env.scene.object_position()
        print(
            f"step {tr.counters.step}: {'pick' if kind == 1 else 'place'} measured at offset (mm) "
            f"{np.round((np.asarray(point) - at) * 1000, 1)}; the part as planned (seen, mm) {np.round(at * 1000, 1)}, "
            f"the twin's part now (mm) {np.round(part * 1000, 1)}; pick measurements before: "
            f"{len(expert.fusion.measured[1])}"
        )
        measured(kind, point)

    expert._measured = traced
    tr.run(stop_at=250)
    tr.close()
