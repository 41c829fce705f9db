"""The particle populations numbered on the device at the end of the searching PFs' step
(``kernels/population_numbers.py``, ``step(…, quota=…)``) and eliminated and handed over from there
(``SearchingPool.eliminate_and_hand_over_numbered``): the same outcome, bit for bit, as the host's numbering
(``slab_populations``, ``eliminated_per_population``) and ``eliminate_and_hand_over`` after a step that reads the
Seq, on both engines, with the step alone or paired with the tracking pool."""
import numpy as np
import pytest

from tbd_taichi.errors import ParameterError
from tbd_taichi.numpy_kernels.populations import eliminated_per_population, slab_populations
from tbd_taichi.methods.sgds.searching_pool import SearchingPool
from tbd_taichi.particles import ParticlePool

from test_populations import pool_engine


def engine_layout(engine: str, monkeypatch) -> str:
    """``pool_engine``, and "taichi-flat": the GPUs' layout (one thread per slot, the unfused step, parallel
    loops over groups) on the CPU."""
    if engine == "taichi-flat":
        import tbd_taichi.particles as particles

        monkeypatch.setattr(particles, "one_thread_per_slot", lambda arch: True)
        return "taichi"
    return pool_engine(engine, monkeypatch)

SHAPE = (23, 31)
CAPS = [1500, 40, 1300, 7, 900]
QUOTA = 120


def seq_labels(kind: str, rng, n: int) -> np.ndarray:
    """Seq labels of n particles: a few values (0 and a far one among them), each its own (the most populations a
    group can hold), negative to large (a wide span), or one value."""
    if kind == "few":
        return rng.choice(np.array([0, 1, 2, 3, 5, 8, 13, 100_000], np.int32), n)
    if kind == "distinct":
        return rng.permutation(n).astype(np.int32) * 3 + 1
    if kind == "wide":
        return rng.integers(-2**31, 2**31 - 1, n, dtype=np.int64).astype(np.int32) // 1000 * 1000 + \
            rng.integers(0, 4, n).astype(np.int32)
    return np.full(n, 42, np.int32)


def pools(engine: str, kind: str, rng_seed: int = 0):
    """A searching pool (groups of several sizes, one empty, one of 7) with random states and Seq labels of
    ``kind``, and a tracking pool to pair it with."""
    rng = np.random.default_rng(rng_seed)
    search = SearchingPool(CAPS, SHAPE, engine=engine, seed=3)
    search.configure_groups(np.arange(len(CAPS)), "uniform", pb=0.2, pd=0.1, intensity=(2.0, 9.0))
    states = {}
    for g, n in enumerate([1500, 0, 1100, 7, 900]):
        if n:
            states[g] = dict(x=rng.uniform(-1, SHAPE[1], n), y=rng.uniform(-1, SHAPE[0], n),
                             vx=rng.uniform(-1, 1, n), vy=rng.uniform(-1, 1, n), inten=rng.uniform(1, 9, n),
                             e=(rng.random(n) < 0.7).astype(np.int32), tp=rng.integers(1, 9, n),
                             seq=seq_labels(kind, rng, n))
    search.set_state(states)
    tracks = ParticlePool([300, 300], SHAPE, engine=engine, seed=5)
    tracks.configure_groups([0, 1], "copy", vmax=1.0, intensity=(1.0, 3.0))
    tracks.set_state({0: dict(x=rng.uniform(0, 30, 300), y=rng.uniform(0, 22, 300), vx=np.zeros(300),
                              vy=np.zeros(300), inten=np.full(300, 4.0), e=np.ones(300, np.int32),
                              tp=np.ones(300, np.int32), seq=np.zeros(300, np.int32))})
    return search, tracks


def run(engine: str, kind: str, numbered: bool, paired: bool, frames: int = 3):
    """Each frame's hand-over members, sizes, index image and the pool's state after it."""
    search, tracks = pools(engine, kind)
    rng = np.random.default_rng(11)
    z = rng.standard_normal((frames,) + SHAPE).astype(np.float32) * 0.5  # weak weights: most parents survive
    out = []
    for f in range(frames):
        index = np.zeros(SHAPE, np.int32)
        read = {"quota": QUOTA} if numbered else {"seq_out": np.empty(search.capacity, np.int32)}
        got = search.step_with(tracks, f, z[f], **read)[0] if paired else search.step(f, z[f], **read)
        rule = (0.0, 0.3, [(5.0, 5.0)], 2.0, 3)  # T_PTp, T_PE, one track, radius, most
        if numbered:
            n_pp = got
            members, sizes = search.eliminate_and_hand_over_numbered(np.random.default_rng(f).random(n_pp), index,
                                                                     *rule)
        else:
            pp_block, inverse, counts = slab_populations(search.counts, got)
            n_pp = len(counts)
            phase = np.random.default_rng(f).random(n_pp)
            take = eliminated_per_population(pp_block, counts, QUOTA)
            members, sizes = search.eliminate_and_hand_over(inverse, counts, take, phase, index, *rule)
        out.append((n_pp, sizes, members, index, search.state(), search.counts.copy()))
    return out


def assert_same(a, b, rtol: float = 0.0):
    """The same runs: bit for bit, or with ``rtol`` on the float states (the two engines' propagation may differ
    in the last bit of a float)."""
    for (n_a, sizes_a, members_a, index_a, state_a, counts_a), (n_b, sizes_b, members_b, index_b, state_b,
                                                                counts_b) in zip(a, b):
        assert n_a == n_b and sizes_a == sizes_b
        np.testing.assert_array_equal(index_a, index_b)
        np.testing.assert_array_equal(counts_a, counts_b)
        for states_a, states_b in ((members_a, members_b), (state_a, state_b)):
            for key in states_a:
                np.testing.assert_allclose(states_a[key], states_b[key], rtol=rtol, atol=rtol, err_msg=key)


@pytest.mark.parametrize("kind", ["few", "distinct", "wide", "one"])
@pytest.mark.parametrize("engine", ["taichi", "taichi-parallel", "taichi-flat", "numpy"])
def test_numbered_on_the_device_as_on_the_host(engine, kind, monkeypatch):
    """Numbered in the step, then eliminated and handed over: the same populations, quotas, hand-overs, index image
    and surviving particles as the host's numbering of the Seq the step read."""
    engine = engine_layout(engine, monkeypatch)
    numbered = run(engine, kind, numbered=True, paired=False)
    assert_same(numbered, run(engine, kind, numbered=False, paired=False))
    n_pp = [n for n, *_ in numbered]
    if kind == "one":  # one population in each of the 4 live groups, until hand-overs empty groups
        assert n_pp[0] == 4
    else:
        assert n_pp[0] > (1000 if kind in ("distinct", "wide") else 4) and min(n_pp) > 4
    assert sum(len(sizes) for _, sizes, *_ in numbered) > 0  # something was handed over


@pytest.mark.parametrize("kind", ["few", "distinct"])
def test_numbered_in_the_paired_step(kind):
    """``step_with`` (the searching and tracking pools in one launch) numbers as ``step`` does, and the engines
    agree (the NumPy engine steps the two pools one after the other)."""
    paired = run("taichi", kind, numbered=True, paired=True)
    assert_same(paired, run("taichi", kind, numbered=False, paired=True))
    assert_same(paired, run("numpy", kind, numbered=True, paired=True), rtol=1e-6)


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_numbered_needs_its_step(engine):
    search, _ = pools(engine, "few")
    z, index = np.zeros(SHAPE, np.float32), np.zeros(SHAPE, np.int32)
    rule = (0.0, 0.3, [], 2.0, 1)
    with pytest.raises(ParameterError, match="quota just before"):
        search.eliminate_and_hand_over_numbered([], index, *rule)
    n_pp = search.step(0, z, None, False, None, None, QUOTA)  # the quota by position too
    with pytest.raises(ParameterError, match="one phase per population"):
        search.eliminate_and_hand_over_numbered(np.zeros(n_pp + 1), index, *rule)
    with pytest.raises(ParameterError, match=r"\[0, 1\)"):
        search.eliminate_and_hand_over_numbered(np.full(n_pp, 1.0), index, *rule)
    with pytest.raises(ParameterError, match="index image"):  # a refused call leaves the numbers usable
        search.eliminate_and_hand_over_numbered(np.zeros(n_pp), np.zeros((2, 2), np.int32), *rule)
    search.eliminate_and_hand_over_numbered(np.zeros(n_pp), index, *rule)
    with pytest.raises(ParameterError, match="quota just before"):  # the numbers are used up
        search.eliminate_and_hand_over_numbered(np.zeros(n_pp), index, *rule)
    n_pp = search.step(1, z, quota=QUOTA)
    search.step(2, z)  # a step without a quota: the numbers no longer hold
    with pytest.raises(ParameterError, match="quota just before"):
        search.eliminate_and_hand_over_numbered(np.zeros(n_pp), index, *rule)
    with pytest.raises(ParameterError, match="either"):
        search.step(1, z, quota=QUOTA, seq_out=np.empty(search.capacity, np.int32))
    for bad in (-1, 2 ** 31, 2.5):
        with pytest.raises(ParameterError, match="quota must be"):
            search.step(1, z, quota=bad)
    plain = ParticlePool([50], SHAPE, engine=engine)
    with pytest.raises(ParameterError, match="do not number"):
        plain.step(0, z, quota=QUOTA)


CHANGES = {  # every way the pool's particles change between a numbered step and the elimination
    "set_state": lambda pool: pool.set_state({0: dict(x=np.full(60, 3.0), y=np.full(60, 4.0), vx=np.zeros(60),
                                                      vy=np.zeros(60), inten=np.full(60, 5.0),
                                                      e=np.ones(60, np.int32), tp=np.ones(60, np.int32),
                                                      seq=np.arange(60, dtype=np.int32) + 900)}),
    "set_counts": lambda pool: pool.set_counts(pool.counts // 2),
    "keep": lambda pool: pool.keep(np.arange(int(pool.counts.sum())) % 2 == 0),
    "predict": lambda pool: pool.predict(9, top_up=pool.counts),
    "resample": lambda pool: pool.resample(9),
    "eliminate": lambda pool: pool.eliminate(*host_numbers(pool)),
}


def host_numbers(pool):
    """(pp, size, take, phase) of the pool's populations, numbered on the host."""
    pp_block, inverse, counts = slab_populations(pool.counts, pool.seq_in_state_order())
    return inverse, counts, eliminated_per_population(pp_block, counts, QUOTA), np.zeros(len(counts))


@pytest.mark.parametrize("change", sorted(CHANGES))
@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_numbers_go_stale_when_the_pool_changes(engine, change):
    """After any change of the pool the device's numbers no longer describe its particles: the numbered
    elimination refuses to run, on both engines, instead of handing over with stale sizes or populations."""
    search, _ = pools(engine, "few")
    n_pp = search.step(0, np.zeros(SHAPE, np.float32), quota=QUOTA)
    assert n_pp > 4
    CHANGES[change](search)
    with pytest.raises(ParameterError, match="no change of the pool"):
        search.eliminate_and_hand_over_numbered(np.zeros(n_pp), np.zeros(SHAPE, np.int32), 0.0, 0.3, [], 2.0, 1)


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_a_zero_quota_eliminates_nothing(engine):
    search, _ = pools(engine, "few")
    n_pp = search.step(0, np.zeros(SHAPE, np.float32), quota=0)
    live = int(search.counts.sum())
    _, sizes = search.eliminate_and_hand_over_numbered(np.full(n_pp, 0.5), np.zeros(SHAPE, np.int32), 1e9, 1.0, [],
                                                        2.0, 0)  # no potential target: nothing handed over
    assert sizes == [] and int(search.counts.sum()) == live
