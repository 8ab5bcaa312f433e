"""The room a seal has on a part's face, and a taught grasp moved the least it must to where a seal has room."""

import numpy as np
import pytest

from mrguide.grasp_margin import SEAL_MARGIN, seal_margins, steady_grasp
from mrguide.parts import PARTS


def test_the_margin_is_what_the_lip_has_left_before_it_leaves_the_face():
    block, plate = PARTS["block"], PARTS["hole_plate"]
    # the 5 cm block: 25 mm to its edges less the 20 mm lip; 4 mm off the centre, 1 mm
    assert seal_margins(block, [[0.0, 0.0], [0.004, 0.0]]) == pytest.approx([0.005, 0.001], abs=6e-4)
    # the plate's frame: 35-50 mm from the centre along y seals, the middle of it has 7.5 mm either side
    m = seal_margins(plate, [[0.0, -0.0425], [0.0, -0.0378], [0.0, -0.03], [0.0, 0.0]])
    assert m[:3] == pytest.approx([0.0075, 0.0028, -0.005], abs=6e-4) and m[3] == -np.inf  # over the hole: no face


def test_a_taught_grasp_moves_the_least_it_must_and_never_beyond_the_intent():
    plate, keepout = PARTS["hole_plate"], PARTS["keepout_block"]
    moved = steady_grasp(plate, [0.0, -0.0378], 0.0085)  # 2.8 mm from the hole's edge
    assert moved == pytest.approx([0.0, -0.040], abs=6e-4)  # out to where the lip has 5 mm
    assert seal_margins(plate, [moved])[0] >= SEAL_MARGIN - 1e-9
    kept = steady_grasp(keepout, [-0.0375, 0.002], 0.0085)  # beside the label, 8 mm of room: the person's point
    assert kept == pytest.approx([-0.0375, 0.002], abs=1e-9)
    far = steady_grasp(plate, [0.0, -0.02], 0.0085)  # over the hole's edge: as far as the intent allows, no further
    assert np.linalg.norm(far - [0.0, -0.02]) <= 0.0085 + 1e-9 and far[1] == pytest.approx(-0.0285, abs=6e-4)


def test_the_seal_window_about_a_grasp_is_what_the_face_leaves_per_axis():
    """The runtime's registration estimate reads a press against this window: 5 mm per axis about the block's centre
    (the 20 mm lip on the 5 cm face), 7.5 mm across the plate's frame and the full reach along it, 7.5 mm towards the
    keep-out block's end and 10 mm across it."""
    from mrguide.grasp_margin import seal_window

    assert seal_window(PARTS["block"], np.zeros(2)) == pytest.approx((0.005, 0.005), abs=6e-4)
    assert seal_window(PARTS["hole_plate"], np.array([0.0, -0.0425])) == pytest.approx((0.03, 0.0075), abs=6e-4)
    assert seal_window(PARTS["keepout_block"], np.array([-0.0375, 0.0])) == pytest.approx((0.0075, 0.01), abs=6e-4)
