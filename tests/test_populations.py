"""Eq. 37–38 population kernels (SearchingPool.eliminate / hand_over): Taichi against the NumPy twin and
against a direct host reference."""
import numpy as np
import pytest

from tbd_taichi.errors import ParameterError
from tbd_taichi.kernels.loops import block_class, frame_class
from tbd_taichi.kernels.populations import P_KEPT, P_KEPT_E, P_TP, P_X, P_Y, pixel_class
from tbd_taichi.numpy_kernels.populations import (eliminated_per_population, populations, slab_populations,
                                                  spread_removal)
from tbd_taichi.methods.sgds.searching_pool import SearchingPool

SHAPE = (19, 27)
CAPS = [900, 40, 1300, 5]


def pool_engine(engine, monkeypatch):
    """The pool engine for a test parameter; "taichi-parallel" runs the parallel loops (large pools,
    GPUs) on the CPU instead of one serial task."""
    if engine == "taichi-parallel":
        import tbd_taichi.particles as particles

        monkeypatch.setattr(particles, "SERIAL_PARTICLES", 0)
        monkeypatch.setattr(particles, "SERIAL_THREADS", 0)  # also on a 2-core machine
        return "taichi"
    return engine


def make_pool(engine, rng_seed=0):
    """Groups of several sizes (one empty), Seq labels 0…7 with a large one, positions also outside the image."""
    rng = np.random.default_rng(rng_seed)
    pool = SearchingPool(CAPS, SHAPE, engine=engine, seed=2)
    counts = [700, 0, 1300, 5]
    states = {}
    for g, n in enumerate(counts):
        if n:
            seq = rng.choice(np.array([0, 1, 2, 3, 5, 8, 13, 100_000], np.int32), n)
            states[g] = dict(x=rng.uniform(-2, SHAPE[1] + 1, n), y=rng.uniform(-2, SHAPE[0] + 1, n),
                             vx=rng.uniform(-1, 1, n), vy=rng.uniform(-1, 1, n), inten=rng.uniform(1, 9, n),
                             e=(rng.random(n) < 0.7).astype(np.int32), tp=rng.integers(1, 9, n), seq=seq)
    pool.set_state(states)
    return pool


def host_reference(st, inverse, counts, take, phase, drop, shape):
    """Eqs. 37–38 and P_pp written out directly on the host state."""
    order = np.argsort(inverse, kind="stable")
    rank = np.empty_like(inverse)
    rank[order] = np.arange(len(inverse)) - (np.cumsum(counts) - counts)[inverse[order]]
    keep = ~spread_removal(rank, counts[inverse], take[inverse], phase[inverse])
    sums = np.zeros((len(counts), 5))
    for s in range(len(inverse)):  # one particle at a time, in state order
        if keep[s]:
            k = inverse[s]
            sums[k, P_KEPT] += 1
            sums[k, P_TP] += st["tp"][s]
            if st["e"][s] == 1:
                sums[k, P_KEPT_E] += 1
                sums[k, P_X] += np.float64(st["x"][s])
                sums[k, P_Y] += np.float64(st["y"][s])
    final = keep & ~drop[inverse]
    index = np.zeros(shape, np.int32)
    best = {}
    for s in np.flatnonzero(final):
        x, y = int(np.floor(st["x"][s] + np.float32(0.5))), int(np.floor(st["y"][s] + np.float32(0.5)))
        if 0 <= x < shape[1] and 0 <= y < shape[0] and st["seq"][s] > 0:
            key = (counts[inverse[s]], s)
            if key > best.get((y, x), (-1, -1)):
                best[(y, x)] = key
                index[y, x] = st["seq"][s]
    return keep, sums, final, index


@pytest.mark.parametrize("engine", ["taichi", "taichi-parallel", "numpy"])
def test_eliminate_and_hand_over_match_the_host_reference(engine, monkeypatch):
    engine = pool_engine(engine, monkeypatch)
    pool = make_pool(engine)
    st = pool.state()
    np.testing.assert_array_equal(pool.seq_in_state_order(), st["seq"])
    buffer = np.full(pool.capacity + 3, -7, np.int32)
    seq = pool.seq_in_state_order(out=buffer)
    assert np.shares_memory(seq, buffer) and np.all(buffer[len(seq):] == -7)
    np.testing.assert_array_equal(seq, st["seq"])
    with pytest.raises(ParameterError, match="int32"):
        pool.seq_in_state_order(out=np.zeros(pool.capacity, np.int64))
    pp_block, inverse, counts = populations(st["group"], st["seq"])
    take = eliminated_per_population(pp_block, counts, 300)
    take[0], take[-1] = 0, counts[-1]  # none and all of a population go
    rng = np.random.default_rng(7)
    phase = rng.random(len(counts))
    phase[1] = 0.0
    drop = rng.random(len(counts)) < 0.3
    keep_ref, sums_ref, final_ref, index_ref = host_reference(st, inverse, counts, take, phase, drop, SHAPE)
    keep, sums = pool.eliminate(inverse, counts, take, phase)
    np.testing.assert_array_equal(keep, keep_ref)
    np.testing.assert_array_equal(sums, sums_ref)  # same order of f64 additions: same bits
    np.testing.assert_array_equal(np.bincount(inverse, weights=~keep, minlength=len(counts)), take)  # Eq. 37 quotas
    index = np.full(SHAPE, -5, np.int32)
    handed = rng.permutation(np.flatnonzero(drop))[:4]  # handed-over PPs, in a shuffled order
    handed = np.append(handed, 0)  # PP 0 loses none to elimination
    members, sizes = pool.hand_over(drop, index, handed)
    np.testing.assert_array_equal(index, index_ref)
    picked = np.concatenate([np.flatnonzero(keep_ref & (inverse == k)) for k in handed])  # PP after PP, state order
    assert sizes == [int((keep_ref & (inverse == k)).sum()) for k in handed] and sum(sizes) == len(picked) > 0
    for key in ("x", "vx", "y", "vy", "inten", "e", "tp", "seq"):
        np.testing.assert_array_equal(members[key], st[key][picked], err_msg=key)
    after = pool.state()
    for key in ("x", "vx", "y", "vy", "inten", "e", "tp", "seq", "group"):
        np.testing.assert_array_equal(after[key], st[key][final_ref], err_msg=key)
    np.testing.assert_array_equal(pool.counts, np.bincount(st["group"][final_ref], minlength=len(CAPS)))


def test_states_at_reads_the_chosen_particles():
    pool = make_pool("taichi", rng_seed=3)
    st = pool.state()
    pick = np.array([0, 5, 699, 700, 1999, 2004])
    sub = pool.states_at(pick)
    for key in st:
        np.testing.assert_array_equal(sub[key], st[key][pick], err_msg=key)


def test_population_arguments_are_checked():
    pool = make_pool("taichi")
    n = int(pool.counts.sum())
    with pytest.raises(ParameterError, match="one population index per live particle"):
        pool.eliminate(np.zeros(n - 1), [n], [0], [0.5])
    with pytest.raises(ParameterError, match="population indices"):
        pool.eliminate(np.full(n, 3), [n], [0], [0.5])
    with pytest.raises(ParameterError, match="take in"):
        pool.eliminate(np.zeros(n), [n], [n + 1], [0.5])
    with pytest.raises(ParameterError, match="take in"):
        pool.eliminate(np.zeros(n), [n], [1], [1.0])
    with pytest.raises(ParameterError, match="needs an eliminate first"):
        pool.hand_over(np.zeros(1, bool), np.zeros(SHAPE, np.int32))
    pool.eliminate(np.zeros(n), [n], [1], [0.5])
    with pytest.raises(ParameterError, match="one drop flag per population"):
        pool.hand_over(np.zeros(2, bool), np.zeros(SHAPE, np.int32))
    with pytest.raises(ParameterError, match="index image"):
        pool.hand_over(np.zeros(1, bool), np.zeros((2, 2), np.int32))
    with pytest.raises(ParameterError, match="handed populations"):
        pool.hand_over(np.zeros(1, bool), np.zeros(SHAPE, np.int32), [1])
    with pytest.raises(ParameterError, match="handed populations"):
        pool.hand_over(np.zeros(1, bool), np.zeros(SHAPE, np.int32), [0, 0])


@pytest.mark.parametrize("engine", ["taichi", "taichi-parallel", "numpy"])
def test_index_image_prefers_the_larger_population_then_the_later_particle(engine, monkeypatch):
    """Pixel (3, 4): PPs Seq 1 and Seq 2 (two particles each) tie, the later particle wins;
    pixel (6, 2): Seq 3 (three particles) beats the later Seq 4 particle (a PP of one)."""
    engine = pool_engine(engine, monkeypatch)
    pool = SearchingPool([10], SHAPE, engine=engine)
    x = np.array([4, 4, 4, 4, 2, 9, 9, 2], np.float32)
    y = np.array([3, 3, 3, 3, 6, 1, 1, 6], np.float32)
    seq = np.array([1, 2, 1, 2, 3, 3, 3, 4], np.int32)
    pool.set_state({0: dict(x=x + 0.3, y=y - 0.4, vx=0, vy=0, inten=1, e=1, tp=1, seq=seq)})
    _, inverse, counts = populations(np.zeros(8, np.int64), seq)
    keep, _ = pool.eliminate(inverse, counts, np.zeros(len(counts)), np.zeros(len(counts)))
    index = np.zeros(SHAPE, np.int32)
    pool.hand_over(np.zeros(len(counts), bool), index)
    assert index[3, 4] == 2 and index[6, 2] == 3 and index[1, 9] == 3
    assert np.count_nonzero(index) == 3


@pytest.mark.parametrize("seq_span", [7, 1 << 24])  # the table and sort paths of populations
def test_populations_number_block_seq_pairs_in_order(seq_span):
    """Against np.unique over (block, Seq) rows: same PP order (block, then Seq), the PP of every
    particle, its block and its size; Seq 0 and a Seq shared by two blocks included."""
    rng = np.random.default_rng(seq_span)
    group = np.sort(rng.integers(0, 5, 3001))
    seq = rng.integers(0, seq_span, 3001)
    seq[::97] = 0
    seq[group == 3] = seq[group == 2][:1] if (group == 2).any() else 5
    pairs, inverse_ref, counts_ref = np.unique(np.stack([group, seq], 1), axis=0, return_inverse=True,
                                               return_counts=True)
    pp_block, inverse, counts = populations(group, seq.astype(np.int32))
    np.testing.assert_array_equal(pp_block, pairs[:, 0])
    np.testing.assert_array_equal(inverse, inverse_ref.reshape(-1))
    np.testing.assert_array_equal(counts, counts_ref)
    empty = populations(np.zeros(0, np.int64), np.zeros(0, np.int32))
    assert all(len(a) == 0 for a in empty)


@pytest.mark.parametrize("seq_span", [7, 5000, 1 << 24])  # a dense table, one over dense Seq ids, the sort
def test_slab_populations_with_empty_blocks_match_unique_pairs(seq_span):
    """Counts per block (empty blocks first, between and last) against np.unique over (block, Seq) rows,
    and against the per-particle block array; the caller's Seq is left as it was."""
    rng = np.random.default_rng(seq_span + 1)
    slabs = np.array([0, 400, 0, 0, 1201, 37, 0])
    group = np.repeat(np.arange(len(slabs)), slabs)
    seq = (rng.integers(0, seq_span, len(group)) + 1000).astype(np.int32)
    seq_before = seq.copy()
    pairs, inverse_ref, counts_ref = np.unique(np.stack([group, seq], 1), axis=0, return_inverse=True,
                                               return_counts=True)
    got = slab_populations(slabs, seq)
    for a, b in zip(got, (pairs[:, 0], inverse_ref.reshape(-1), counts_ref)):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(got, populations(group, seq)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(seq, seq_before)


def host_decisions(sums, t_ptp, t_pe, tracked, radius, most):
    """Algorithm 1's hand-over rule written out PP by PP on the host: (drop flags, handed PPs in order)."""
    drop, handed = np.zeros(len(sums), bool), []
    for k, (n, ne, tp, sx, sy) in enumerate(sums[:, [P_KEPT, P_KEPT_E, P_TP, P_X, P_Y]].tolist()):
        if n > 0 and ne > 0 and tp / n > t_ptp and ne / n > t_pe:
            near = any((sx / ne - tx) ** 2 + (sy / ne - ty) ** 2 < radius ** 2 for tx, ty in tracked)
            if near or len(handed) < most:
                drop[k] = True
            if not near and len(handed) < most:
                handed.append(k)
    return drop, handed


@pytest.mark.parametrize("engine", ["taichi", "taichi-parallel", "numpy"])
@pytest.mark.parametrize("most", [0, 2, 50])
def test_one_launch_hand_over_matches_eliminate_then_hand_over(engine, most, monkeypatch):
    """eliminate_and_hand_over gives the same pool, index image and members as eliminate, the rule decided on
    the host, and hand_over; a track placed on a potential target's mean drops it without a hand-over."""
    engine = pool_engine(engine, monkeypatch)
    two, one = make_pool(engine, rng_seed=5), make_pool(engine, rng_seed=5)
    st = two.state()
    pp_block, inverse, counts = populations(st["group"], st["seq"])
    take = eliminated_per_population(pp_block, counts, 200)
    phase = np.random.default_rng(9).random(len(counts))
    t_ptp, t_pe = 3.0, 0.6
    _, sums = two.eliminate(inverse, counts, take, phase)
    potential = [k for k in range(len(counts)) if host_decisions(sums[k:k + 1], t_ptp, t_pe, [], 2.0, 1)[1]]
    assert len(potential) >= 4  # the test needs potential targets
    k0 = potential[1]
    tracked = [(sums[k0, P_X] / sums[k0, P_KEPT_E] + 1.5, sums[k0, P_Y] / sums[k0, P_KEPT_E] - 1.0), (-50.0, -50.0)]
    drop, handed = host_decisions(sums, t_ptp, t_pe, tracked, 2.0, most)
    assert drop[k0] and k0 not in handed and len(handed) <= most and (most == 0 or len(handed) >= 2)
    index_two, index_one = np.zeros(SHAPE, np.int32), np.full(SHAPE, -3, np.int32)
    members_two, sizes_two = two.hand_over(drop, index_two, handed)
    members_one, sizes_one = one.eliminate_and_hand_over(inverse, counts, take, phase, index_one, t_ptp, t_pe,
                                                         tracked, 2.0, most)
    assert sizes_one == sizes_two
    np.testing.assert_array_equal(index_one, index_two)
    for key in members_two:
        np.testing.assert_array_equal(members_one[key], members_two[key], err_msg=key)
    after_two, after_one = two.state(), one.state()
    for key in after_two:
        np.testing.assert_array_equal(after_one[key], after_two[key], err_msg=key)
    np.testing.assert_array_equal(one.counts, two.counts)


def test_one_launch_hand_over_engines_agree_without_tracks():
    """No active track (an empty list) and no room for hand-overs on both engines: same pool and index image."""
    pools = {engine: make_pool(engine, rng_seed=8) for engine in ("taichi", "numpy")}
    st = pools["numpy"].state()
    pp_block, inverse, counts = populations(st["group"], st["seq"])
    take = eliminated_per_population(pp_block, counts, 100)
    phase = np.random.default_rng(4).random(len(counts))
    out = {}
    for engine, pool in pools.items():
        index = np.zeros(SHAPE, np.int32)
        members, sizes = pool.eliminate_and_hand_over(inverse, counts, take, phase, index, 2.0, 0.5, [], 2.0, 3)
        out[engine] = (index, members, sizes, pool.state())
    assert len(out["numpy"][2]) == 3
    assert out["taichi"][2] == out["numpy"][2]
    np.testing.assert_array_equal(out["taichi"][0], out["numpy"][0])
    for key in out["numpy"][1]:
        np.testing.assert_array_equal(out["taichi"][1][key], out["numpy"][1][key], err_msg=key)
    for key in out["numpy"][3]:
        np.testing.assert_array_equal(out["taichi"][3][key], out["numpy"][3][key], err_msg=key)


@pytest.mark.parametrize("shape, entries", [((1, 1), 1 << 19), ((40, 50), 1 << 19), ((256, 320), 1 << 19),
                                            ((512, 640), 1 << 19), ((724, 724), 1 << 19), ((725, 724), 1 << 20),
                                            ((1025, 1030), 1 << 21)])
def test_pixel_class_holds_every_pixel_in_a_power_of_two_of_at_least_the_floor(shape, entries):
    """The searching pool's per-pixel tables hold every pixel: the pixel count rounded up to a power of two, at
    least 2^19 (724 × 724 px), so every frame up to that area shares one class."""
    assert pixel_class(shape) == entries >= shape[0] * shape[1]


@pytest.mark.parametrize("blocks, groups", [(1, 8), (2, 8), (6, 8), (8, 8), (9, 16), (12, 16), (16, 16), (17, 32)])
def test_block_class_is_a_power_of_two_of_at_least_8(blocks, groups):
    assert block_class(blocks) == groups


@pytest.mark.parametrize("shape, rows, columns", [((1, 1), 256, 320), ((40, 50), 256, 320), ((233, 297), 256, 320),
                                                  ((256, 320), 256, 320), ((100, 330), 256, 384),
                                                  ((257, 321), 512, 384), ((1025, 1030), 2048, 1088)])
def test_frame_class_rounds_rows_to_a_power_of_two_and_columns_to_64_px(shape, rows, columns):
    """The saliency stage's size classes (``loops.frame_class``): at least 256 × 320, so every smaller frame
    shares one class."""
    assert frame_class(shape) == (rows, columns)
