"""`gc_sac.philox`: Random123's Philox-4x32-10 in torch integer ops, as per-seed streams that do not
depend on the stack around a seed, on how many seeds there are, or on the device."""

import numpy as np
import pytest
import torch

from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams, philox4x32

# Random123's published known-answer vectors for philox4x32_10: (counter, key) -> output.
KNOWN_ANSWERS = [
    ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
    ((0xFFFFFFFF,) * 4, (0xFFFFFFFF,) * 2, (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
    (
        (0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344),
        (0xA4093822, 0x299F31D0),
        (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1),
    ),
]


def _reference(counter, key):
    """Philox-4x32-10 with Python's unbounded ints: written from the algorithm's definition, not from
    the module's wrapping int64 arithmetic."""
    c, (k0, k1) = list(counter), key
    for r in range(10):
        if r:
            k0, k1 = (k0 + 0x9E3779B9) % 2**32, (k1 + 0xBB67AE85) % 2**32
        p0, p1 = 0xD2511F53 * c[0], 0xCD9E8D57 * c[2]
        c = [(p1 >> 32) ^ c[1] ^ k0, p1 % 2**32, (p0 >> 32) ^ c[3] ^ k1, p0 % 2**32]
    return tuple(c)


@pytest.mark.parametrize(("counter", "key", "expected"), KNOWN_ANSWERS)
def test_the_published_known_answers(counter, key, expected):
    out = philox4x32([torch.tensor(c) for c in counter], [torch.tensor(k) for k in key])
    assert tuple(int(w) for w in out) == expected
    assert _reference(counter, key) == expected  # the reference is right too


def test_random_counters_and_keys_match_the_unbounded_integer_reference():
    rng = np.random.default_rng(0)
    counters = rng.integers(0, 2**32, (200, 4), dtype=np.int64)
    keys = rng.integers(0, 2**32, (200, 2), dtype=np.int64)
    out = philox4x32(
        [torch.as_tensor(counters[:, i]) for i in range(4)], [torch.as_tensor(keys[:, i]) for i in range(2)]
    )
    got = np.stack([w.numpy() for w in out], axis=1)
    want = np.array(
        [_reference(tuple(map(int, c)), tuple(map(int, k))) for c, k in zip(counters, keys, strict=True)]
    )
    np.testing.assert_array_equal(got, want)
    assert got.min() >= 0 and got.max() < 2**32


def test_a_stream_is_reproducible_and_continues_across_draws():
    a, b = PhiloxStreams([7], purpose=1), PhiloxStreams([7], purpose=1)
    first = torch.cat([a.words(4), a.words(8)], dim=1)
    np.testing.assert_array_equal(first.numpy(), b.words(12).numpy())
    assert a.counters.tolist() == [3]
    assert not torch.equal(a.words(4), first[:, :4])  # the counter moved: new numbers


def test_a_seed_draws_the_same_alone_and_anywhere_in_a_stack_of_any_size():
    alone = {s: PhiloxStreams([s], purpose=2) for s in (3, 11)}
    stack = PhiloxStreams([5, 11, 3, 8], purpose=2)
    pair = PhiloxStreams([11, 3], purpose=2)
    for shape in ((5,), (3, 2), (7,)):
        got = stack.normal(shape)
        got_pair = pair.normal(shape)
        for s, stream in alone.items():
            want = stream.normal(shape)[0]
            assert torch.equal(got[stack.seeds.index(s)], want)
            assert torch.equal(got_pair[pair.seeds.index(s)], want)
    assert not torch.equal(got[0], got[2])  # different seeds, different numbers


def test_an_inactive_seed_keeps_its_stream_where_it_was():
    stack, alone = PhiloxStreams([1, 2], purpose=0), PhiloxStreams([2], purpose=0)
    stack.uniform(6, active=torch.tensor([True, False]))
    assert stack.counters.tolist() == [2, 0]
    assert torch.equal(stack.uniform(6)[1], alone.uniform(6)[0])


def test_purposes_and_seeds_above_32_bits_give_unrelated_streams():
    base = PhiloxStreams([9], purpose=0).words(16)
    assert not torch.equal(base, PhiloxStreams([9], purpose=1).words(16))
    assert not torch.equal(base, PhiloxStreams([9 + 2**32], purpose=0).words(16))
    with pytest.raises(ValueError, match=r"seed must be in \[0, 2\*\*64\)"):
        PhiloxStreams([-1], purpose=0)


def test_uniform_and_normal_moments():
    streams = PhiloxStreams([0, 1], purpose=3)
    u32, u64 = streams.uniform(100_000), streams.uniform(50_000, dtype=torch.float64)
    for u in (u32, u64):
        assert 0.0 <= float(u.min()) and float(u.max()) < 1.0
        assert abs(float(u.mean()) - 0.5) < 0.005
        assert abs(float(u.var()) - 1 / 12) < 0.002
        counts = torch.histc(u[0].float(), bins=10, min=0.0, max=1.0)
        assert float((counts / u.shape[1] - 0.1).abs().max()) < 0.01
    assert u32.dtype == torch.float32 and u64.dtype == torch.float64 and float(u32.min()) > 0.0
    z = streams.normal((400, 250))
    assert z.shape == (2, 400, 250) and z.dtype == torch.float32
    assert abs(float(z.mean())) < 0.01 and abs(float(z.std()) - 1.0) < 0.01
    assert abs(float((z**3).mean())) < 0.03 and abs(float((z**4).mean()) - 3.0) < 0.06
    assert abs(float((z.flatten()[:-1] * z.flatten()[1:]).mean())) < 0.01  # neighbours uncorrelated


def test_a_checkpoint_restores_the_counters_in_place_and_refuses_other_streams():
    streams = PhiloxStreams([4, 5], purpose=6)
    streams.words(9)
    state = streams.get_state()
    after = streams.words(5)
    counters = streams.counters
    streams.set_state(state)
    assert streams.counters is counters  # the same tensor: a captured graph keeps reading it
    assert torch.equal(streams.words(5), after)
    with pytest.raises(ValueError, match="does not fit these streams"):
        PhiloxStreams([4, 6], purpose=6).set_state(state)


def test_one_stream_of_a_stack_shares_its_counter_and_draws_what_the_stack_draws_for_it():
    stack = PhiloxStreams([3, 4, 5], purpose=7)
    middle = stack.stream(1)
    alone = PhiloxStreams([4], purpose=7)
    assert torch.equal(middle.words(6), alone.words(6))
    assert stack.counters.tolist() == [0, 2, 0]  # the stack's counter of seed 4 moved with it
    assert torch.equal(stack.words(4)[1], alone.words(4)[0])
    assert middle.counters.tolist() == [3]
