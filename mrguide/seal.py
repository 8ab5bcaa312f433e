"""The suction cup's seal, the same for every engine: when the lip rests on a face of the part, the vacuum level the
generator reaches through what of the lip hangs past the face, and the force that level holds.

Both engines (`twin.suction`, `mujoco_cell.plant`) call these with the cup's pose in the part's frame; neither has
a seal rule of its own. Levels are in kPa below atmosphere (positive); lengths in m; forces in N.

**The lip rests on a face** when the cup points at it, square to it within `MAX_TILT`, its lip within
`LIP_COMPLIANCE` of it (a lip further off leaves a ring-shaped gap 2πr·h open all round: 10 µm of it is already
more than the generator can evacuate, below). Pressed further in, the lip is compressed, and it still rests.

**The face is the part's material nearest the lip** (`mrguide.parts`: a part is a few boxes): the highest of the box
faces under the lip's disc, with every face at that height; the disc over a hole, past an edge, over lower material
or against higher material is not on it.

**Where the lip hangs past the face's edge it leaks.** The lip's disc (radius `CUP_RADIUS`) beyond the face is an
opening to the atmosphere (a sagging lip can only narrow it, so its area errs strict), an orifice in parallel with
the generator. The generator is an ejector of linear characteristic, suction flow Q(p) = Q₀ (1 − p / p_sealed); the
opening passes at most its choked flow Q_leak = C_d · a · √(R T) · ψ* (air from the atmosphere; exact above 47 kPa,
within 4 % at the 35 kPa part threshold, an over-estimate below, so again strict). The level settles where they
balance, p = p_sealed (1 − Q_leak / Q₀), and never below what the generator reads with the cup wide open:

    level = max(p_open, p_sealed · (1 − a / A_LEAK))        A_LEAK = Q₀ / (C_d √(R T) ψ*) ≈ 1.1 mm²

So an opening of about 1 mm² — a lip hanging 0.2 mm past the edge, 4 % of its circumference — takes most of the
vacuum: the seal ends where the whole lip leaves the face, as a real cup's does. The part-present threshold then
says whether the level suffices.

**The level holds** F = Δp · A (A = π r², Schmalz's theoretical holding force, no safety factor): a pull off the face
up to F, a shear along it up to μ (F − pull) (the vacuum presses the lip on the face, friction carries the shear).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mrguide.cell_layout import CUP_RADIUS
from mrguide.parts import Box

#: m the lip may stand off a face and still rest on it: a flat cup's lip (a Ø40 mm flat cup, the class the cell's
#: 20 mm lip is) deforms by about a millimetre; assumed, the order of such a lip's travel. A bellows cup would allow
#: several millimetres.
LIP_COMPLIANCE = 0.001
#: The cup's axis may tilt this far off the face's normal (rad): the lip's diameter then spans 2r·tan θ of height,
#: which its compliance must take up: atan(1 mm / 40 mm) = 1.4°.
MAX_TILT = math.atan(LIP_COMPLIANCE / (2.0 * CUP_RADIUS))
COS_MAX_TILT = math.cos(MAX_TILT)
#: The cup's area (m²): what the pressure difference acts on.
CUP_AREA = math.pi * CUP_RADIUS**2
#: m³/s, the generator's free suction flow: Schmalz's design guide sizes it at 0.5 m³/h for a cup up to Ø60 mm on a
#: smooth, airtight part ("Design of the suction cup", typical volume flow).
FREE_FLOW = 0.5 / 3600.0
#: Discharge coefficient of a sharp-edged orifice (0.61-0.65).
DISCHARGE_COEFFICIENT = 0.62
#: Air at 20 °C: specific gas constant (J/(kg K)), temperature (K), heat-capacity ratio.
GAS_CONSTANT, TEMPERATURE, GAMMA = 287.0, 293.0, 1.4
#: Choked flow function ψ* = √γ (2 / (γ + 1))^((γ + 1) / (2 (γ − 1))): 0.685 for air.
CHOKED = math.sqrt(GAMMA) * (2.0 / (GAMMA + 1.0)) ** ((GAMMA + 1.0) / (2.0 * (GAMMA - 1.0)))
#: m², the opening whose choked flow equals the generator's free flow: there the level reaches nothing.
LEAK_AREA = FREE_FLOW / (DISCHARGE_COEFFICIENT * math.sqrt(GAS_CONSTANT * TEMPERATURE) * CHOKED)
#: m: faces of two boxes this close in height are one face (the plate's frame is four boxes).
COPLANAR = 1e-9
#: m²: an open area below this is the rounding of several faces' sum, not an opening (a millionth of `LEAK_AREA`).
AREA_ROUNDING = 1e-12
#: Friction of the lip on the part: Schmalz's reference value for dry, smooth workpieces (μ = 0.5).
LIP_FRICTION = 0.5


@dataclass(frozen=True)
class LipOnFace:
    """The cup against the part's material it points at."""

    rests: bool  # square to the face and within the lip's compliance of it
    open_area: float  # m², the lip's disc not on the face: past its edges, over a hole, over higher material


def leak_level(open_area: float, sealed: float, open_level: float) -> float:
    """The level (kPa below atmosphere) the generator reaches with `open_area` m² of the lip open (module docstring):
    `sealed` with the lip whole on the face, falling linearly to nothing at `LEAK_AREA`, never below `open_level`."""
    return max(open_level, sealed * (1.0 - open_area / LEAK_AREA))


def _chord_integral(x0: float, x1: float, r: float) -> float:
    """∫ √(r² − x²) dx from x0 to x1 (−r ≤ x0, x1 ≤ r)."""

    def antiderivative(x: float) -> float:
        return 0.5 * (x * math.sqrt(max(r * r - x * x, 0.0)) + r * r * math.asin(x / r))

    return antiderivative(x1) - antiderivative(x0)


def _disc_below(a: float, b: float, r: float) -> float:
    """Area of the disc of radius r about the origin where x ≤ a and y ≤ b."""
    a = min(a, r)
    if a <= -r or b <= -r:
        return 0.0
    if b >= r:
        return 2.0 * _chord_integral(-r, a, r)
    s = math.sqrt(r * r - b * b)  # for |x| < s the chord crosses y = b: b + √(r² − x²) of it lies below
    area = (b * (min(s, a) + s) + _chord_integral(-s, min(s, a), r)) if a > -s else 0.0
    if b >= 0.0:  # for |x| ≥ s the whole chord lies below
        area += 2.0 * _chord_integral(-r, min(-s, a), r)
        if a > s:
            area += 2.0 * _chord_integral(s, a, r)
    return area


def open_area(centre: tuple[float, float], half: tuple[float, float], r: float = CUP_RADIUS) -> float:
    """Area (m²) of the disc of radius `r` about `centre` outside the rectangle ±`half` (the face, in its plane)."""
    if abs(centre[0]) + r <= half[0] and abs(centre[1]) + r <= half[1]:
        return 0.0  # the whole disc on the face (exactly: the sum below rounds)
    x0, x1 = -half[0] - centre[0], half[0] - centre[0]
    y0, y1 = -half[1] - centre[1], half[1] - centre[1]
    inside = _disc_below(x1, y1, r) - _disc_below(x0, y1, r) - _disc_below(x1, y0, r) + _disc_below(x0, y0, r)
    return max(0.0, math.pi * r * r - inside)


def _face_axis(axis: Sequence[float]) -> int:
    """The axis of a box whose faces the cup's `axis` (in the box's frame) points at: the one it is most along."""
    return max(range(3), key=lambda n: abs(axis[n]))


def face_normal(axis: np.ndarray) -> np.ndarray:
    """The outward normal of the face of a box the cup's `axis` (in the box's frame) points at."""
    k = _face_axis(axis.tolist())
    normal = np.zeros(3)
    normal[k] = -math.copysign(1.0, float(axis[k]))
    return normal


def lip_on_face(rel: np.ndarray, axis: np.ndarray, boxes: Sequence[Box]) -> LipOnFace | None:
    """The lip against the part's faces it points at, or None if it points away or no material lies under its disc.

    `rel` is the lip's centre and `axis` the cup's axis (out of the lip), both in the part's frame; `boxes` the part's
    material. Of the boxes' faces facing the cup under the lip's disc, the highest (nearest the lip) is what it rests
    on, and the disc seals only on faces at that height: over lower material, a hole or past the edges it is open."""
    r, a = rel.tolist(), axis.tolist()
    k = _face_axis(a)  # the faces' normal is ±axis k of the part
    out = -math.copysign(1.0, a[k])
    i, j = (n for n in range(3) if n != k)
    lip = out * r[k]  # the lip's height along the faces' outward normal
    if all(lip <= out * b.centre[k] - b.half[k] for b in boxes):
        return None  # the cup points away from the part: the lip lies behind all of it
    faces = []  # (height, in-plane centre, in-plane half) of each face under the lip's disc
    for b in boxes:
        centre, half = (r[i] - b.centre[i], r[j] - b.centre[j]), (b.half[i], b.half[j])
        if max(abs(centre[0]) - half[0], 0.0) ** 2 + max(abs(centre[1]) - half[1], 0.0) ** 2 < CUP_RADIUS**2:
            faces.append((out * b.centre[k] + b.half[k], centre, half))
    if not faces:
        return None
    top = max(f[0] for f in faces)
    level = [f for f in faces if top - f[0] <= COPLANAR]
    area = open_area(level[0][1], level[0][2])
    if len(level) > 1:  # the other faces cover some of what lies past the first; their sum rounds
        area -= sum(CUP_AREA - open_area(c, h) for _, c, h in level[1:])
        area = area if area > AREA_ROUNDING else 0.0
    rests = lip - top <= LIP_COMPLIANCE and abs(a[k]) >= COS_MAX_TILT
    return LipOnFace(rests, area)


def level_reached(rel: np.ndarray, axis: np.ndarray, boxes: Sequence[Box], sealed: float, open_level: float) -> float:
    """The level the generator reaches with the cup at this pose (`lip_on_face`'s arguments): the leak's level where
    the lip rests on a face, the open cup's elsewhere."""
    lip = lip_on_face(rel, axis, boxes)
    if lip is None or not lip.rests:
        return open_level
    return leak_level(lip.open_area, sealed, open_level)


def holding_force(level: float) -> float:
    """N the cup holds off a face at `level` kPa below atmosphere: Δp · A."""
    return max(level, 0.0) * 1e3 * CUP_AREA


def holds(pull: float, shear: float, level: float) -> bool:
    """Whether the cup at `level` (kPa) holds a part pulled off its face by `pull` N (negative: pressed on it) and
    along it by `shear` N."""
    force = holding_force(level)
    return pull <= force and shear <= LIP_FRICTION * (force - pull)
