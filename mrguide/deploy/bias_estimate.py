"""The pose source's registration bias, estimated from the cell's own grasps.

Every press of the cup says something about where the part really was: the lip seals only where it rests whole on
the part's face, within a window about the grasp (`SealWindow`: 5 mm per axis about the centre of the 5 cm block's
top for the 20 mm lip, `mrguide.seal`; about a taught grasp, what the part's face leaves there). A press at p that
sealed says the part's grasp point lies within that window of p; one that did not, that it lies outside. The pose
source saw the part at s = centre + b (its mean of the looks while the part stood still), so each press is a
measurement of the bias b, blurred by what remains of the looks' error: `LOOK_SIGMA` over the square
root of the looks in the mean, and the arm's `ARM_SIGMA`. `BiasEstimate` keeps
the posterior of b on a 1 mm grid of ±`RANGE` per axis, starting from a normal prior of `PRIOR_SIGMA` per axis, and
its mean is what the runtime subtracts from the source's poses. The same posterior says where a press most likely
seals (`best_press`): where the seal search presses next. The estimate is saved after each update and read back at the next start (`save`, `load`),
so that the cell improves its registration with every part it picks, across runs.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

#: m: the bias range the grid covers per axis (ours: three times the HMD's 5 mm calibration error).
RANGE = 0.015
#: m: the prior's standard deviation per axis (ours: the cells' HMD's 5 mm calibration error).
PRIOR_SIGMA = 0.005
#: m: the grid's spacing.
STEP = 0.001
#: m: the standard deviation per axis of one look's error: the cells' HMD at the part (3 mm and 0.3° per frame; a
#: camera's is smaller, so this errs soft).
LOOK_SIGMA = 0.005
#: m: the arm's error in where the cup presses against where it was commanded (ours).
ARM_SIGMA = 0.0005


def blur(looks: int) -> float:
    """The standard deviation (m) of a press's offset from the source's mean of `looks` looks."""
    return math.sqrt(LOOK_SIGMA**2 / max(looks, 1) + ARM_SIGMA**2)


def _erf(x: np.ndarray) -> np.ndarray:
    return np.vectorize(math.erf, otypes=[float])(x)


@dataclass(frozen=True)
class SealWindow:
    """Where a press seals: the cup's axis within `half` (m, x and y) of `centre` (m, x and y in the part's frame:
    the grasp point), per axis."""

    centre: tuple[float, float]
    half: tuple[float, float]


class BiasEstimate:
    """The posterior of the source's xy bias b (seen = true + b), from presses that sealed or did not."""

    def __init__(self, window: SealWindow) -> None:
        self.window = window
        axis = np.arange(-RANGE, RANGE + STEP / 2, STEP)
        self._bx, self._by = np.meshgrid(axis, axis, indexing="ij")
        self._log = -(self._bx**2 + self._by**2) / (2 * PRIOR_SIGMA**2)  # log posterior up to a constant
        cells = np.arange(axis.size)
        self._apart = np.abs(cells[:, None] - cells[None, :]) * STEP  # m between the grid's cells along an axis
        (hx, hy) = window.half
        self._box_x, self._box_y = (
            (self._apart <= hx + STEP / 2),
            (self._apart <= hy + STEP / 2),
        )  # the window, per axis
        self.presses = 0
        self.seals = 0

    def _inside(self, offset: float, b: np.ndarray, sigma: float, half: float) -> np.ndarray:
        """P(|offset + b| < half) along one axis for each bias b on the grid, offset = press − seen − the window's
        centre, blurred by `sigma`."""
        s = sigma * math.sqrt(2.0)
        return 0.5 * (_erf((half - offset - b) / s) - _erf((-half - offset - b) / s))

    def press(self, tcp: np.ndarray, seen: np.ndarray, sealed: bool, sigma: float) -> None:
        """A press of the cup at `tcp` (m) on the part the source saw at `seen` (its raw mean, m): sealed or not;
        `sigma` (m) the press's blur (`blur`)."""
        (cx, cy), (hx, hy) = self.window.centre, self.window.half
        ox, oy = float(tcp[0] - seen[0] - cx), float(tcp[1] - seen[1] - cy)
        p = self._inside(ox, self._bx, sigma, hx) * self._inside(oy, self._by, sigma, hy)
        self._log += np.log(np.clip(p if sealed else 1.0 - p, 1e-12, 1.0))
        self._log -= self._log.max()
        self.presses += 1
        self.seals += int(sealed)

    @property
    def estimate(self) -> np.ndarray:
        """The posterior mean of the bias (m, xy); zero before any press."""
        w = np.exp(self._log)
        w /= w.sum()
        return np.array([(w * self._bx).sum(), (w * self._by).sum()])

    def best_press(self, missed: list[np.ndarray], sigma: float) -> np.ndarray:
        """The offset (m, xy) from the source's mean pose at which the next press on this part most likely seals: the
        window's placement that holds the most mass of where this part's grasp point lies, from the bias's posterior
        blurred by this part's look error `sigma` (m, `blur`) less the offsets this part was `missed` at (each ruled
        out up to the arm's `ARM_SIGMA`: the same part, the same look error)."""
        smear = np.exp(-0.5 * (self._apart / max(sigma, 1e-6)) ** 2)  # this part's look error, per axis
        here = smear @ np.exp(self._log) @ smear.T
        (cx, cy), (hx, hy) = self.window.centre, self.window.half
        for ox, oy in missed:
            here *= 1.0 - self._inside(ox - cx, self._bx, ARM_SIGMA, hx) * self._inside(
                oy - cy, self._by, ARM_SIGMA, hy
            )
        box = self._box_x @ here @ self._box_y.T  # the window's mass about each cell
        i, j = np.unravel_index(int(np.argmax(box)), box.shape)
        # sealed where |press - seen - centre + b| < half: the window about b* is hit by press = seen + centre - b*
        return np.array([cx - self._bx[i, j], cy - self._by[i, j]])

    def save(self, path: Path, source: str) -> None:
        """Write the posterior to `path` (JSON), naming the pose source it belongs to."""
        state = {"source": source, "presses": self.presses, "seals": self.seals, "window": asdict(self.window)}
        state["log_posterior"] = np.round(self._log, 6).tolist()
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(json.dumps(state))
        tmp.replace(path)

    @classmethod
    def load(cls, path: Path, source: str, window: SealWindow) -> BiasEstimate | None:
        """The estimate saved at `path` for the same source and window (a file from before the window was a
        `SealWindow` is another window); None if there is none. ValueError for a file that is not one (named, with
        what is wrong)."""
        if not path.exists():
            return None
        try:
            state = json.loads(path.read_text())
            log = np.asarray(state["log_posterior"], dtype=float)
            saved = state["window"]
            same = state["source"] == source and saved == json.loads(json.dumps(asdict(window)))
            est = cls(window)
            if log.shape != est._log.shape or not np.all(np.isfinite(log)):
                raise ValueError(f"a posterior of shape {log.shape}, expected {est._log.shape}")
            presses, seals = int(state["presses"]), int(state["seals"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"{path}: not a bias estimate ({exc}); delete it to start afresh") from exc
        if not same:
            return None
        est._log, est.presses, est.seals = log, presses, seals
        return est


class Registration:
    """The runtime's use of the estimate: each decision, the presses it saw reported; the correction to subtract
    from the pose source's poses returned. Saved to `path` (if any) after every press, read from it at the start."""

    def __init__(self, window: SealWindow, source: str, path: Path | None = None) -> None:
        self.source, self.path = source, path
        loaded = BiasEstimate.load(path, source, window) if path is not None else None
        self.estimate = loaded or BiasEstimate(window)
        self._sealed = False  # this episode's seal was reported
        self._missed: list[np.ndarray] = []  # where (m, xy) this part was pressed without a seal

    def reset(self) -> None:
        """A new episode."""
        self._sealed, self._missed = False, []

    def aim(self, seen: np.ndarray, looks: int) -> np.ndarray:
        """Where (m, xy) the next press on the part the source sees at `seen` (its raw mean of `looks` looks) most
        likely seals, after this episode's presses that did not."""
        seen = np.asarray(seen, dtype=float)[:2]
        return seen + self.estimate.best_press([m - seen for m in self._missed], blur(looks))

    @property
    def correction(self) -> np.ndarray:
        """What to subtract from the source's poses (m, xyz: the bias's xy, no height)."""
        return np.array([*self.estimate.estimate, 0.0])

    def after_decision(
        self, tcp: np.ndarray, seen: np.ndarray | None, looks: int, grasping: bool, gripped: bool, reseat: bool
    ) -> bool:
        """Report this decision's press, if it made one: a re-seat (the cup pressed at `tcp` without a seal) or the
        grasp's first seal; `seen` is the source's mean pose of the part (uncorrected) over `looks` looks. True if the
        estimate moved."""
        if seen is None or not grasping or not (reseat or (gripped and not self._sealed)):
            return False
        self._sealed = self._sealed or gripped
        if reseat:
            self._missed.append(np.asarray(tcp, dtype=float)[:2].copy())
        self.estimate.press(tcp, seen, gripped and not reseat, blur(looks))
        if self.path is not None:
            self.estimate.save(self.path, self.source)
        return True
