"""Tagged replay: the realized expert ratio follows λ within sampling error and respects the cap."""

import numpy as np
import pytest

from mrguide.policies.replay_buffer import RingBuffer, TaggedReplay


def filled(n_agent, n_expert, cap=10_000):
    rp = TaggedReplay(cap, 3, 2)
    for i in range(n_agent):
        rp.add(np.full(3, i), np.zeros(2), 0.0, np.zeros(3), False, 0)
    for i in range(n_expert):
        rp.add(np.full(3, -1 - i), np.ones(2), 1.0, np.zeros(3), False, 1)
    return rp


@pytest.mark.parametrize("lam", [0.1, 0.5, 0.9])
def test_realized_ratio_matches_lambda(lam):
    rp = filled(5000, 5000)
    rng = np.random.default_rng(0)
    ratios = [rp.sample(256, lam, rng).expert_ratio for _ in range(400)]
    se = np.sqrt(lam * (1 - lam) / (256 * 400))
    assert abs(np.mean(ratios) - lam) < 4 * se
    b = rp.sample(256, lam, rng)
    # the mask and the stored data agree: expert rows have action 1
    assert np.array_equal(b.expert, b.act[:, 0] == 1.0)
    assert b.expert.mean() == pytest.approx(b.expert_ratio)


def test_ratio_capped_by_expert_pool_size():
    rp = filled(5000, 20)
    rng = np.random.default_rng(1)
    for _ in range(50):
        b = rp.sample(256, 0.9, rng)
        assert b.expert.sum() <= 20
        assert b.expert_ratio == pytest.approx(20 / 256)


def test_only_one_pool_filled():
    rng = np.random.default_rng(2)
    assert filled(100, 0).sample(64, 0.9, rng).expert_ratio == 0.0
    assert filled(0, 100).sample(64, 0.1, rng).expert_ratio == 1.0
    with pytest.raises(ValueError, match="empty"):
        filled(0, 0).sample(64, 0.5, rng)


def test_ring_buffer_wraps_and_round_trips():
    rb = RingBuffer(5, 1, 1)
    for i in range(8):
        rb.add([i], [i], i, [i], False)
    assert rb.size == 5
    st = rb.state()
    assert st["rew"].tolist() == [3, 4, 5, 6, 7]  # oldest first
    rb2 = RingBuffer(5, 1, 1)
    rb2.load(st)
    assert rb2.state()["rew"].tolist() == [3, 4, 5, 6, 7]
    with pytest.raises(ValueError, match="shape"):
        RingBuffer(5, 2, 1).load(st)


def test_million_transitions_fit_and_filling_allocates_nothing_more():
    """Memory as numpy allocates it (tracemalloc sees every array): both pools of 1e6 transitions take
    2 × 1e6 × 112 B (float32: obs, next_obs 11, act 4, reward, done) at construction, and filling them
    through `add` past the wrap-around allocates nothing that stays."""
    import tracemalloc

    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        rp = TaggedReplay(1_000_000, 11, 4)
        built = tracemalloc.get_traced_memory()[0] - base
        obs = np.ones(11, np.float32)
        for i in range(3000):
            rp.add(obs * i, np.zeros(4, np.float32), 1.0, obs, i % 7 == 0, i % 2)
        grown = tracemalloc.get_traced_memory()[0] - base - built
    finally:
        tracemalloc.stop()
    assert 2 * 1_000_000 * 112 <= built < 2 * 1_000_000 * 112 * 1.01  # ≈ 224 MB (213.6 MiB), nothing else
    assert grown < 100_000
    assert len(rp) == 3000 and rp.expert.obs.dtype == np.float32
