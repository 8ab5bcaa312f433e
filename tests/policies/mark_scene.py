"""The scene the marks tests share: a part, a goal, and an observation of them in a phase."""

import numpy as np

from mrguide.task import observation

OBJ, GOAL = np.array([0.5, -0.1, 0.025]), np.array([0.5, 0.2, 0.025])


def scene_obs(phase, obj=OBJ, goal=GOAL, tcp=(0.5, 0.1, 0.3), g=-1):
    """The observation with the TCP at `tcp`, vacuum `g`, in `phase`, of the part at `obj` and the goal at `goal`."""
    return observation(np.array(tcp), g, phase / 5, np.asarray(obj), np.asarray(goal))
