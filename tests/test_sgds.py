"""SGDS-PF end to end (Algorithms 1–2) and its confirmation arithmetic (Eqs. 40–43)."""
import math
from collections import deque

import numpy as np
import pytest
import scipy.ndimage as ndi

import tbd_taichi as tbd
from tbd_taichi import cli, tables
from tbd_taichi.methods.sgds.params import PAPER_SALIENCY
from tbd_taichi.errors import InputError
from tbd_taichi.frontend import FrontEnd
from tbd_taichi.numpy_kernels.populations import spread_removal
from tbd_taichi.methods.sgds import SGDSPF
from tbd_taichi.methods.sgds.confirmation import (MSW_LEF_OFFSET, held_compact, icef_of_log_ratio, log_weight_ratio,
                                                  msw_from_candidates, scef, update_confidence, windowed_icef)
from tbd_taichi.methods.sgds.populations import resize_population


def run(shape, frames, snr, seed, engine="taichi", **params):
    scene = tbd.simulate(shape, frames, snr=snr, seed=seed)
    tracker = SGDSPF(shape, snr=snr, seed=seed, engine=engine, **params)
    for frame in scene.frames:
        tracker.update(frame)
    return tracker, tracker.finish(), scene


def score(shape, frames, snr, seed, **params) -> dict:
    """tbd.metrics.evaluate of one run against its truth."""
    _, tracks, scene = run(shape, frames, snr, seed, **params)
    return tbd.metrics.evaluate(tracks, scene.truth)


def icef(log_mtw, log_msw):
    """Eq. 40 from the two log-weights, as the tracking step composes it."""
    return icef_of_log_ratio(log_weight_ratio(log_mtw, log_msw))


def test_icef_eq40():
    assert icef(math.log(3.0), 0.0) == pytest.approx(3.0)
    assert icef(math.log(0.5), 0.0) == 1.0
    assert icef(math.log(0.05), 0.0) == 0.9
    assert icef(-3e38, 0.0) == 0.9  # no E = 1 particle in the track
    assert icef(0.0, -3e38) == 1.0  # none in the search PFs


def test_log_weight_ratio_and_its_fallbacks():
    assert log_weight_ratio(1.0, 4.0) == -3.0
    assert log_weight_ratio(-3e38, 4.0) == -50.0  # no E = 1 particle in the track: the worst ratio
    assert log_weight_ratio(1.0, -3e38) == 0.0  # none in the search PFs: neutral (Eq. 40 gives 1)
    assert log_weight_ratio(200.0, 0.0) == 50.0


def test_windowed_icef_lifts_only_a_full_window_of_ratios_above_the_mean():
    window, ratio = 4, 0.05
    low = math.log(0.04)  # r = 0.04 < 0.1: Eq. 40 gives 0.9 for this frame alone
    above, below = [math.log(0.2), low, low, math.log(0.06)], [low] * window  # geometric means 0.069, 0.04
    sums, full = np.array([sum(above), sum(below), 3 * math.log(0.2)]), np.array([True, True, False])
    nine = np.full(3, 0.9)
    assert windowed_icef(nine, sums, full, window, ratio).tolist() == [1.0, 0.9, 0.9]  # the last: not yet full
    assert windowed_icef(nine, sums, full, 1, ratio).tolist() == [0.9] * 3  # window 1: Eq. 40 as printed
    # r ≥ 1 and 0.1 ≤ r < 1 keep Eq. 40's value
    assert windowed_icef(np.array([3.0, 1.0]), sums[[1, 1]], full[:2], window, ratio).tolist() == [3.0, 1.0]


def track_states_run(log_r, compact, icef_window, confirm_window, t_rt, c0=1.0):
    """One track's C, N_rt and confirmation frame through ``TrackStates.step`` (ln MSW 0, so ln MTW = ln r; SCEF
    1.1 where ``compact``, else 0.9; T_ft 0, so it never ends; ICEF's 0.1 and the windows' ratios as at 200×200)."""
    from tbd_taichi.methods.sgds.track_states import TrackStates

    states, confirmed_at = TrackStates(1, icef_window, confirm_window), None
    states.start(0, 0, 5.0, 5.0)
    states.confidence[0] = c0
    rule = ((10, 10), 0.0, t_rt, 0.1, 0.05, math.log(0.03))
    for f, (lr, tight) in enumerate(zip(log_r, compact)):
        ended = states.step(f, np.array([True]), np.array([[5.0, 5.0]]), np.array([lr]), 0.0,
                            np.array([1.1 if tight else 0.9]), rule)
        assert not ended[0]
        if confirmed_at is None and states.confirmed[0]:
            confirmed_at = f
    return float(states.confidence[0]), int(states.n_rt[0]), confirmed_at


def test_windowed_icef_lets_a_faint_compact_track_reach_c_equal_1():
    """A compact track (SCEF 1.1) whose r sits at 0.04–0.08, as a target's does at SNR 1.2 (its ln r has
    median −3.4 against the search PFs' noise maximum): Eq. 40 alone gives C·0.9·1.1 < 1 every frame, so
    N_rt stays 0 and the track is never confirmed; with the 10-frame window C returns to 1 each frame."""
    rng = np.random.default_rng(0)
    log_r = np.log(rng.uniform(0.04, 0.08, 40))
    for window, expect_confirmed in ((1, False), (10, True)):
        c, n_rt, confirmed_at = track_states_run(log_r, [True] * 40, window, 0, t_rt=5)
        assert (n_rt > 5) == expect_confirmed == (confirmed_at is not None), (window, n_rt, c)


def test_held_compact_needs_a_full_window_of_compact_frames_above_the_mean():
    window, floor = 5, math.log(0.03)
    above = [math.log(r) for r in (0.02, 0.05, 0.03, 0.04, 0.03)]  # geometric mean 0.033
    cases = np.array([[True, True], [True, False], [False, True], [True, True]])  # compact, full
    sums = np.array([sum(above), sum(above[:4]), sum(above), window * math.log(0.025)])
    # full and above; not yet full; one frame with SCEF < 1; below the mean
    assert held_compact(cases[:, 0], sums, cases[:, 1], window, floor).tolist() == [True, False, False, False]
    assert held_compact(cases[:1, 0], sums[:1], cases[:1, 1], 0, floor).tolist() == [False]  # window 0: N_rt alone


def test_long_window_confirms_a_faint_compact_track_that_c_never_does():
    """A compact track (SCEF 1.1) whose r sits at 0.028–0.045, as a target's did over 115 frames at SNR 1.2
    (200×200, seed 52: ln r about −3.5 against the ICEF window's ln 0.05 = −3.0): ICEF is 0.9 in every frame,
    C shrinks by 0.99 per frame and N_rt stays 0; the 30-frame window (mean ratio 0.03) confirms it once
    the window is full, and not if the cloud spreads in one frame of every 20, as noise tracks' clouds do."""
    rng = np.random.default_rng(1)
    log_r = np.log(rng.uniform(0.028, 0.045, 100))
    for spread_every, expect_frame in ((0, 29), (20, None)):
        compact = [not spread_every or f % spread_every != spread_every - 1 for f in range(100)]
        _, n_rt, confirmed_at = track_states_run(log_r, compact, 10, 30, t_rt=10 ** 6, c0=0.5)
        assert n_rt == 0 and confirmed_at == expect_frame, (spread_every, n_rt, confirmed_at)


@pytest.mark.slow
def test_long_window_only_adds_confirmations():
    """200×200, SNR 1.2, scenario seeds 55 and 60, each tracked by a compact but faint tracking PF: with
    confirm_window 0 (Eq. 43 alone) neither target is found; the 30-frame window finds both (measured DSR
    0.55 and 0.67) and confirms no noise track.  The window decides confirmation only, so every track
    Eq. 43 confirms is reported with the same rows either way.  Over seeds 50–79 and 90–119 the window
    found 4 more targets (55, 56, 60, 104) with the same false tracks (1, in seed 77) and the same rows
    for every track Eq. 43 confirms.  Measured with Algorithm 2's uniform hand-over draw (handover_frames 0), which
    this test keeps: with the SNR 1.2 preset's multi-frame hand-over one of the two targets is found with the
    window and one without it, so these two seeds no longer isolate the window."""
    found = {0: 0, 30: 0}
    for seed in (55, 60):
        runs = {window: run((200, 200), 150, 1.2, seed, confirm_window=window, handover_frames=0)
                for window in (0, 30)}
        paper, windowed = runs[0][1], runs[30][1]
        truth = runs[0][2].truth
        kept = np.isin(windowed["track_id"], paper["track_id"])
        np.testing.assert_array_equal(windowed[kept], paper)
        for window, (_, tracks, _) in runs.items():
            scores = tbd.metrics.evaluate(tracks, truth)
            found[window] += scores["dsr"] > 0.2
            assert scores["false_tracks"] == 0, (seed, window, scores)
    assert found == {0: 0, 30: 2}, found


@pytest.mark.slow
def test_paper_saliency_with_the_icef_window_confirms_faint_targets():
    """200×200, SNR 1.2, scenario seeds 30–37, with the paper's saliency and MSW (the setting the window
    was chosen in) and the 10-frame window: measured DSR 0.00, 0.70, 0.55, 0.91, 0.00, 0.70, 0.88, 0.25
    (6 of 8 found, no false track), the same with Eq. 40 alone (icef_window 1) and without the long
    confirmation window on the current build (an earlier one gave 5 with Eq. 40 alone).  Eight runs cannot
    separate the two (over seeds 20–59 the window lifted TSR from 0.65 to 0.75); the test above pins the
    mechanism, this one that the chain still confirms faint targets."""
    scores = [score((200, 200), 150, 1.2, seed, icef_window=10, **PAPER_SALIENCY) for seed in range(30, 38)]
    assert sum(s["dsr"] > 0.2 for s in scores) >= 5, scores
    assert sum(s["false_tracks"] for s in scores) == 0, scores


def test_icef_window_threshold_follows_the_frame_area():
    """icef_mean_ratio holds at 200×200; MSW grows with the area (ln MSW ≈ 0.45·ln(H·W)), so smaller
    frames need a larger mean ratio and larger frames a smaller one; exponent 0 turns the scaling off."""
    p = tbd.SGDSParams.for_snr(1.2)
    assert p.icef_ratio_for(200 * 200) == p.icef_mean_ratio == 0.05
    assert p.icef_ratio_for(50 * 50) == pytest.approx(0.05 * 16 ** 0.45)  # 0.174
    assert p.icef_ratio_for(1024 * 1024) == pytest.approx(0.05 * (40000 / 1024 ** 2) ** 0.45)
    assert p.icef_ratio_for(4 * 4) == 1.0  # capped: never stricter than Eq. 40's r ≥ 1
    assert tbd.SGDSParams.for_snr(1.2, icef_area_exponent=0).icef_ratio_for(50 * 50) == 0.05
    assert SGDSPF((50, 50), snr=1.2).icef_ratio == pytest.approx(0.05 * 16 ** 0.45)
    # Eq. 40's own bound 0.1 scales the same way: printed at 200×200, stricter in smaller frames
    assert SGDSPF((200, 200), snr=1.2).icef_lower == 0.1
    assert SGDSPF((50, 50), snr=1.2).icef_lower == pytest.approx(0.1 * 16 ** 0.45)  # 0.348
    assert p.icef_ratio_for(320 * 256, 0.1) == pytest.approx(0.1 * (40000 / 81920) ** 0.45)  # 0.072
    assert icef_of_log_ratio(math.log(0.2)) == 1.0 and icef_of_log_ratio(math.log(0.2), 0.348) == 0.9
    # and so does the long confirmation window's mean ratio (0.03 at 200×200)
    assert SGDSPF((200, 200), snr=1.2).confirm_log_ratio == pytest.approx(math.log(0.03))
    assert SGDSPF((50, 50), snr=1.2).confirm_log_ratio == pytest.approx(math.log(0.03 * 16 ** 0.45))  # 0.104


def test_area_scaled_icef_window_drops_a_small_frame_false_track():
    """50×50, SNR 1.4, scenario seed 18, with the paper's saliency and MSW (the setting the scaling was
    chosen in): the 200×200 threshold (exponent 0) confirms a noise track, the area-scaled one does not,
    and the target is found either way.  Over seeds 0–49 the scaling took the false tracks from 10 to 3
    and TSR from 0.96 to 0.92 (docs/results/suite_analysis.md)."""
    scores = {}
    for exponent in (0.0, 0.45):
        _, tracks, scene = run((50, 50), 70, 1.4, 18, icef_area_exponent=exponent, **PAPER_SALIENCY)
        scores[exponent] = tbd.metrics.evaluate(tracks, scene.truth)
    assert scores[0.0]["false_tracks"] >= 1 and scores[0.0]["dsr"] > 0.8, scores[0.0]
    assert scores[0.45]["false_tracks"] == 0 and scores[0.45]["dsr"] > 0.8, scores[0.45]


def test_msw_from_candidates_skips_tracked_candidates():
    """The first candidate outside ±2 px of every track, plus the offset; the last value if all are
    tracked; −3e38 (Eq. 40's fallback, ICEF = 1) without candidates."""
    w = 100
    best = np.array([[9.0, 10 * w + 20], [7.0, 50 * w + 50], [6.0, 11 * w + 21], [-3.0e38, -1.0]])
    assert msw_from_candidates(best, w, []) == 9.0 + MSW_LEF_OFFSET
    assert msw_from_candidates(best, w, [(21.6, 9.4)]) == 7.0 + MSW_LEF_OFFSET  # (20, 10) is 1–2 px away
    assert msw_from_candidates(best, w, [(23.0, 10.0)]) == 9.0 + MSW_LEF_OFFSET  # 3 px away: not tracked
    assert msw_from_candidates(best, w, [(20.0, 10.0), (50.0, 50.0)]) == 6.0 + MSW_LEF_OFFSET
    assert msw_from_candidates(best[:2], w, [(20.0, 10.0), (50.0, 50.0)]) == 7.0 + MSW_LEF_OFFSET
    none = np.array([[-3.0e38, -1.0]] * 4)
    assert msw_from_candidates(none, w, []) == -3.0e38
    assert log_weight_ratio(2.0, msw_from_candidates(none, w, [])) == 0.0


def test_ended_tracks_pfs_are_empty_after_the_frame():
    """A track's group is freed when it ends and its tracking PF is emptied by the frame's track load (or by
    a count update when no track starts): after every frame the tracking pool holds N_tpf particles in
    the groups of the active tracks and none elsewhere."""
    scene = tbd.simulate((64, 64), 30, snr=1.4, seed=3)
    tracker = SGDSPF((64, 64), snr=1.4, seed=3, max_tracks=4)
    ended = 0
    for frame in scene.frames:
        before = {t.group for t in tracker.active}
        tracker.update(frame)
        after = {t.group for t in tracker.active}
        ended += len(before - after)
        want = np.zeros(4, np.int64)
        want[sorted(after)] = tracker.p.N_tpf
        np.testing.assert_array_equal(tracker.tracks_pool.counts, want)
        state = tracker.tracks_pool.state()  # read from the device: the counts it holds
        np.testing.assert_array_equal(np.bincount(state["group"], minlength=4), want)
    assert ended >= 3  # tracks did end (and groups were reused: 4 groups only)


def test_proposal_maps_are_each_blocks_support_in_pixel_order(rng):
    """SGDSPF._proposal_maps against a pass per block: 130×251 at the SNR 1.2 preset (L_ib 100: 2×3
    blocks of unequal sizes), a sparse random proposal with one block left empty."""
    tracker = SGDSPF((130, 251), snr=1.2, engine="numpy")
    proposal = np.where(rng.random((130, 251)) < 0.05, rng.random((130, 251)), 0.0).astype(np.float32)
    proposal[tracker.grid.block_id == 4] = 0
    maps = tracker._proposal_maps(proposal, proposal > 0)
    block = tracker.grid.block_id.ravel()
    expected = {b: np.flatnonzero((block == b) & (proposal.ravel() > 0)) for b in range(tracker.grid.n_blocks)}
    assert sorted(maps) == [b for b, pix in expected.items() if len(pix)] == [0, 1, 2, 3, 5]
    for b, (pix, weights) in maps.items():
        np.testing.assert_array_equal(pix, expected[b])
        assert weights.dtype == np.float64
        np.testing.assert_array_equal(weights, proposal.ravel()[pix])


def test_pp_labels_keep_existing_ids_and_number_new_components(rng):
    """Eq. 36 (SGDSPF._labels): support pixels with a P_pp id keep it; the others get new ids
    next_pp − 1 + k by 8-connected component k (same partition as scipy.ndimage.label); 0 elsewhere."""
    tracker = SGDSPF((61, 47), snr=1.4, engine="numpy")
    support = ndi.binary_dilation(rng.random((61, 47)) < 0.02, iterations=1)
    support[0, :] = support[-1, -5:] = True  # components along the borders
    tracker.pp_index[10:20, 10:20] = 7
    tracker.next_pp = 40
    labels = tracker._labels(support)
    reference, n = ndi.label(support, structure=np.ones((3, 3)))
    assert tracker.next_pp == 40 + n
    assert np.all(labels[~support] == 0)
    old = support & (tracker.pp_index != 0)
    assert old.any() and np.all(labels[old] == 7)
    new = support & ~old
    for k in range(1, n + 1):  # one new id per component, distinct across components
        ids = np.unique(labels[new & (reference == k)])
        assert len(ids) <= 1 and (len(ids) == 0 or 40 <= ids[0] < 40 + n)
    firsts = [np.unique(labels[new & (reference == k)]) for k in range(1, n + 1)]
    assert len({int(i[0]) for i in firsts if len(i)}) == sum(len(i) > 0 for i in firsts)


def proposal_mass_near_target(seed: int, **params) -> float:
    """Mean over frames 10–57 of the share of the whole frame's proposal (OPsal_N, all blocks) within
    1.5 px of the true target: 200×200, SNR 1.2 preset, 60 frames, NumPy engine (deterministic)."""
    p = tbd.SGDSParams.for_snr(1.2, **params)
    scene = tbd.simulate((200, 200), 60, 1.2, seed=seed)
    front = FrontEnd((200, 200), snr=1.2, L_ib=p.L_ib, psf_sigma=p.psf_sigma, background="none", bad_pixels=True,
                     engine="numpy", lef_memory=p.lef_memory, lef_scale=p.lef_scale)
    yy, xx = np.mgrid[:200, :200]
    shares = []
    for frame in scene.frames:
        for out in front.push(frame):
            t = scene.truth[scene.truth["frame"] == out.frame][0]
            near = np.hypot(xx - t["x"], yy - t["y"]) <= 1.5
            shares.append(out.proposal[near].sum(dtype=np.float64) / max(out.proposal.sum(dtype=np.float64), 1e-300))
    return float(np.mean(shares[10:]))


@pytest.mark.slow
def test_multi_frame_lef_puts_more_of_the_proposal_on_faint_targets_than_eq29():
    """The mechanism behind lef_memory: seeds 12–19, the default (multi-frame LEF) against Eq. 29 as
    printed (PAPER_SALIENCY).  Measured: 0.020, 0.004, 0.002, 0.036, 0.129, 0.034, 0.007, 0.012 (mean
    0.031) against 0.002, 0.002, 0.002, 0.005, 0.009, 0.006, 0.001, 0.003 (mean 0.0037): 8.3×, and more
    than 2× on 7 of the 8 seeds.  (What it does to detection is a statistical matter for the suite: over
    its 100 seeds TSR 0.67 → 0.74, mean DSR 0.41 → 0.50, docs/results/suite.md.)"""
    ours = [proposal_mass_near_target(seed) for seed in range(12, 20)]
    paper = [proposal_mass_near_target(seed, **PAPER_SALIENCY) for seed in range(12, 20)]
    assert np.mean(ours) > 4 * np.mean(paper), (ours, paper)
    assert sum(a > 2 * b for a, b in zip(ours, paper)) >= 6, (ours, paper)


def test_scef_eqs41_42_sound_reading():
    t = 2 / 1.3
    assert scef(np.diag([1.0, 1.0]), t) == 1.1
    assert scef(np.diag([9.0, 1.0]), t) == pytest.approx(t / 3)
    anti = np.array([[2.0, -1.9], [-1.9, 2.0]])  # elongated along a diagonal: √cov would be imaginary
    assert scef(anti, t) == pytest.approx(t / math.sqrt(2.0 + 1.9))
    stack = np.stack([np.diag([1.0, 1.0]), np.diag([9.0, 1.0]), anti, np.zeros((2, 2)), np.full((2, 2), np.nan)])
    np.testing.assert_array_equal(scef(stack, t)[:4], [scef(c, t) for c in stack[:4]])  # one value per group
    assert np.isnan(scef(stack, t)[4])  # an empty group's NaN covariance stays NaN (never read)


def test_confidence_eq43():
    assert update_confidence(0.8, 1.0, 1.1) == pytest.approx(0.88)
    assert update_confidence(0.95, 1.0, 1.1) == 1.0
    assert update_confidence(1.0, 0.9, 1.0) == pytest.approx(0.9)


def test_spread_removal_eq37():
    """Exactly ``take`` of each PP go, each particle with probability take/size over random phases,
    and not as one contiguous run (resampled siblings sit together)."""
    size, take = 40, 10
    rank = np.arange(size)
    hits = np.zeros(size)
    rng = np.random.default_rng(0)
    for phase in rng.random(4000):
        gone = spread_removal(rank, np.full(size, size), np.full(size, take), np.full(size, phase))
        assert gone.sum() == take
        assert np.diff(np.flatnonzero(gone)).min() == size // take  # evenly spread
        hits += gone
    np.testing.assert_allclose(hits / 4000, take / size, atol=4 * np.sqrt(0.25 * 0.75 / 4000))
    assert not spread_removal(rank, np.full(size, size), np.zeros(size, np.int64), np.full(size, 0.7)).any()
    assert spread_removal(rank, np.full(size, size), np.full(size, size), np.full(size, 0.999)).all()


def test_resize_population():
    u = np.random.default_rng(0).random(600)
    down = resize_population(800, 500, np.random.default_rng(1).random(800))
    assert len(down) == 500 and len(np.unique(down)) == 500 and down.max() < 800
    up = resize_population(120, 500, u)
    assert len(up) == 500 and set(range(120)) <= set(up.tolist()) and up.max() < 120
    for n, size in ((800, 500), (500, 500), (501, 1), (7, 0)):  # the size smallest uniforms, in index order
        v = np.random.default_rng(n).random(n)
        np.testing.assert_array_equal(resize_population(n, size, v), np.sort(np.argsort(v, kind="stable")[:size]))


@pytest.mark.parametrize("shape,frames,seeds", [((200, 200), 150, range(10)), ((50, 50), 70, range(4))])
def test_snr2_target_is_confirmed_and_followed(shape, frames, seeds):
    """The paper's protocol at SNR 2, its goal mean DSR ≥ 0.8.  At 200×200 (seeds 0–9: 0.97, 0.93, 0.91, 0.95,
    0.95, 0.91, 0.96, 0.95, 0.87, 0.92; the suite's 100 runs: mean 0.93; with the paper's Eq. 29 and MSW, an
    earlier build held it for under 60 % of the frames in 4 of 30 runs, mean 0.84) ten runs must give a
    median ≥ 0.8 with at most two below 0.5, and no false track (the suite: none in 100 runs); at 50×50
    (seeds 0–3: 0.86, 0.89, 0.93, 0.93) every run holds it, with at most one false track in the four (the
    suite: 0.07 per sequence, so two or more in four runs has probability 0.03; seed 1 has one, a noise
    track 10–16 px from the target)."""
    dsrs, false_tracks = [], 0
    for seed in seeds:
        tracker, tracks, scene = run(shape, frames, 2.0, seed)
        scores = tbd.metrics.evaluate(tracks, scene.truth)
        dsrs.append(scores["dsr"])
        false_tracks += scores["false_tracks"]
        assert false_tracks <= (0 if shape[0] >= 200 else 1), (seed, scores)
        assert scores["dsr"] <= 0.2 or scores["edt_mean"] < 0.8, (seed, scores)  # EDT counts above T1 = 0.2
        keys = tracks[["frame", "track_id"]]
        assert len(np.unique(keys)) == len(keys)  # one row per track and frame (Eq. 39's path)
    dsrs = np.array(dsrs)
    assert np.median(dsrs) >= 0.8 and (dsrs < 0.5).sum() <= len(dsrs) // 5, dsrs.round(2)


def test_snr14_target_is_still_found_at_50x50():
    """Measured DSR 0.81, 0.80, 0.00, 0.86 on seeds 0–3 (before SCEF over the E = 1 particles and the
    area-scaled Eq. 40 bound: 0.81, 0.83, 0.73, 0.86).  The suite's TSR here is 0.97, so three of four
    found and a mean DSR ≥ 0.6."""
    dsrs = [tbd.metrics.evaluate(run((50, 50), 70, 1.4, seed)[1], run_truth)["dsr"]
            for seed, run_truth in ((s, tbd.simulate((50, 50), 70, 1.4, seed=s).truth) for s in range(4))]
    assert np.mean(dsrs) >= 0.6 and sum(d > 0.2 for d in dsrs) >= 3, dsrs


def test_snr14_target_is_still_found_at_200x200():
    """Measured DSR 0.00, 0.92, 0.61, 0.97, 0.69, 0.69, 0.73, 0.88 on seeds 0–7: found (DSR > T1 = 0.2)
    in 7 of 8 (seed 6 0.44 before the long confirmation window; before SCEF over the E = 1 particles and
    the sampled statistics 0.00, 0.00, 0.79, 0.81, 0.29, 0.69, 0.96, 0.43, 6 of 8; the 100-test suite: TSR
    0.96, docs/results/suite.md); at least 4 of 8 required."""
    dsrs = []
    for seed in range(8):
        _, tracks, scene = run((200, 200), 150, 1.4, seed)
        dsrs.append(tbd.metrics.evaluate(tracks, scene.truth)["dsr"])
    assert sum(d > 0.2 for d in dsrs) >= 4, np.round(dsrs, 2)


def test_engines_agree():
    paths = []
    for engine in ("taichi", "numpy"):
        _, tracks, scene = run((64, 64), 40, 3.0, 5, engine)
        assert len(np.unique(tracks["track_id"])) == 1
        paths.append({int(r["frame"]): (r["x"], r["y"]) for r in tracks})
    common = sorted(set(paths[0]) & set(paths[1]))
    assert len(common) >= 25
    gap = np.mean([math.dist(paths[0][f], paths[1][f]) for f in common])
    assert gap < 0.5  # same target, same path, up to f32 rounding in the particles


def test_same_tracks_with_one_and_two_threads(tmp_path):
    scene = tbd.simulate((48, 48), 30, 3.0, seed=2)
    np.save(tmp_path / "seq.npy", scene.frames)
    outs = []
    for threads in ("1", "2"):
        out = tmp_path / f"t{threads}.csv"
        assert cli.main(["track", str(tmp_path / "seq.npy"), "--snr", "3", "--seed", "4", "--threads", threads,
                         "--out", str(out)]) == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] and len(outs[0].splitlines()) > 5


def test_online_paths_video_and_plot(tmp_path):
    scene = tbd.simulate((60, 60), 40, 3.0, seed=1)
    np.savez(tmp_path / "seq.npz", frames=scene.frames)
    tables.write_csv(scene.truth, tmp_path / "truth.csv")
    args = ["track", str(tmp_path / "seq.npz"), "--snr", "3", "--truth", str(tmp_path / "truth.csv")]
    assert cli.main(args + ["--out", str(tmp_path / "whole.csv"), "--plot", str(tmp_path / "p.png"),
                            "--video", str(tmp_path / "v.avi")]) == 0
    assert cli.main(args + ["--out", str(tmp_path / "online.csv"), "--paths", "online"]) == 0
    whole, online = tables.read_tracks(tmp_path / "whole.csv"), tables.read_tracks(tmp_path / "online.csv")
    assert 0 < len(online) < len(whole)  # the whole path starts before confirmation
    assert online["frame"].min() > whole["frame"].min()
    assert (tmp_path / "p.png").stat().st_size > 1000
    assert len(tbd.io.read_frames(tmp_path / "v.avi")) == 40


def test_bad_input():
    tracker = SGDSPF((32, 32))
    with pytest.raises(InputError, match=r"frame 0 has shape \(32, 33\)"):
        tracker.update(np.zeros((32, 33)))
    for _ in range(4):
        tracker.update(np.random.default_rng(0).random((32, 32)))
    with pytest.raises(InputError, match="4 frame.*at least 5"):
        tracker.finish()
    with pytest.raises(InputError, match="at least 5"):
        tbd.track(np.zeros((4, 32, 32), np.float32))


def test_history_off_keeps_memory_constant_on_a_long_stream():
    """history=False: no per-frame state accumulates (the 100,000-frame check is
    benchmarks/memory_stream.py); the same frames with history=True do grow, so this can fail."""
    import gc
    import tracemalloc

    scene = tbd.simulate((32, 32), 450, snr=3.0, seed=4, speed=(0.0, 0.0), q1=0.0)  # a still target
    growth = {}
    for history in (False, True):
        tracker = SGDSPF((32, 32), snr=3.0, seed=4, history=history)
        rows = 0
        tracemalloc.start()
        for t, frame in enumerate(scene.frames):
            rows += len(tracker.update(frame))
            if t == 150:
                gc.collect()
                start = tracemalloc.get_traced_memory()[0]
        gc.collect()
        growth[history] = tracemalloc.get_traced_memory()[0] - start
        tracemalloc.stop()
        assert rows > 250  # the target is held either way
    assert growth[False] < 0.3 * growth[True], growth  # True keeps ~300 B of rows and path per frame
    assert growth[True] > 60_000, growth


@pytest.mark.parametrize("method", ["sgds", "pf"])
def test_reused_fields_give_the_same_tracks(method):
    """A second tracker of the same shapes reuses the first one's Taichi fields (no recompile)
    and must not see any of its state."""
    scene = tbd.simulate((40, 40), 30, snr=2.5, seed=6)
    tables_out = []
    for _ in range(2):
        tracker = tbd.make_tracker(method, (40, 40), snr=2.5, seed=3)
        for frame in scene.frames:
            tracker.update(frame)
        tables_out.append(tracker.finish())
        del tracker  # its fields go back to the spare list
    assert len(tables_out[0]) > 10
    np.testing.assert_array_equal(tables_out[0], tables_out[1])


def test_fields_reused_at_another_size_of_the_class_give_the_same_tracks():
    """A tracker at 33 × 40 on the fields (and compiled kernels) a 60 × 60 tracker left, both of the 256 × 320 size
    class (one 8-block class), and the other way round: the same tracks as on fields of its own, so nothing of the larger frame's
    values (rows, columns, pixels past the smaller frame) reaches the smaller one, nor the reverse."""
    import gc

    scenes = {shape: tbd.simulate(shape, 30, snr=2.5, seed=6) for shape in ((33, 40), (60, 60))}

    def run(shape):
        tracker = tbd.SGDSPF(shape, snr=2.5, seed=3)
        for frame in scenes[shape].frames:
            tracker.update(frame)
        return tracker, tracker.finish()

    for shape, other in (((33, 40), (60, 60)), ((60, 60), (33, 40))):
        own, fresh = run(shape)  # kept alive: its fields are not lent
        first, _ = run(other)
        lent = (first.front.saliency.engine.f, first.search.k._target)
        del first
        gc.collect()  # the other size's fields go back to the spare list
        reused, tracks = run(shape)
        assert (reused.front.saliency.engine.f, reused.search.k._target) == lent
        assert len(fresh) > 10
        np.testing.assert_array_equal(tracks, fresh)
        del own, reused
        gc.collect()


def test_peak_z_is_the_3x3_maximum_and_nan_outside():
    from tbd_taichi.peak_guard import peak_z

    z = np.zeros((6, 7), np.float32)
    z[2, 3], z[0, 0], z[5, 6] = 4.0, 9.0, -1.0
    assert peak_z(z, 3.4, 1.6) == 4.0  # nearest pixel (3, 2); the 3×3 around it holds the 4
    assert peak_z(z, 4.6, 2.0) == 0.0  # nearest (5, 2): the 4 at column 3 is 2 px away
    assert peak_z(z, -0.4, 0.2) == 9.0  # the window is cut at the border
    assert np.isnan(peak_z(z, -3.0, 2.0)) and np.isnan(peak_z(z, 2.0, 10.0))


def test_min_peak_z_reports_only_tracks_that_bright():
    """SNR 3 at 50×50: the target's running 3×3 peak z (from 0, weight 0.1) rises to 3.0 (measured):
    min_peak_z = 2 reports the same rows as no gate, 2.5 the same track from 5 frames later (its whole
    path then runs from its first report on), 4 nothing.  The gate changes the output only."""
    scene = tbd.simulate((50, 50), 40, 3.0, seed=5)
    rows, whole = {}, {}
    for gate in (0.0, 2.0, 2.5, 4.0):
        tracker = SGDSPF((50, 50), snr=3.0, seed=5, min_peak_z=gate)
        rows[gate] = [row for frame in scene.frames for row in tracker.update(frame)]
        whole[gate] = tracker.finish()
    assert len(rows[0.0]) > 15 and rows[2.0] == rows[0.0]
    later = rows[2.5]
    assert 0 < len(later) < len(rows[0.0]) and later == rows[0.0][-len(later):]
    span = whole[2.5]  # the whole path from its first report on (finish's rows included)
    assert len(later) <= len(span) < len(whole[0.0]) and span.tobytes() == whole[0.0][-len(span):].tobytes()
    assert rows[4.0] == [] and len(whole[4.0]) == 0
    with pytest.raises(tbd.ParameterError, match="min_peak_z"):
        SGDSPF((50, 50), min_peak_z=-1.0)


def test_keep_peak_z_holds_a_proven_track_through_a_faint_stretch():
    """min_peak_z 16 with keep_peak_z 12 after 5 reported frames: a track at peak z 20 is reported once its running
    peak (from 0, weight 0.1) passes 16; when the peak falls to 13, the proven track stays reported while a track
    reported in fewer frames is cut at 16 as before; below 12 both are cut.  keep_peak_z 0 is the plain gate."""
    from tbd_taichi.methods.sgds.confirmation import Track

    def reported(keep_after: int, keep: float, peaks) -> list[bool]:
        tracker = SGDSPF((20, 20), min_peak_z=16.0, keep_peak_z=keep, keep_after=keep_after)
        t, out = Track(1, 0, confirmed=True, path=deque([(0, 10.0, 10.0, 0, 0, 1, 1)])), []
        for f, peak in enumerate(peaks):
            z = np.zeros((20, 20), np.float32)
            z[10, 10] = peak
            t.path.append((f, 10.0, 10.0, 0, 0, 1, 1))
            tracker.states.xy[0] = (10.0, 10.0)
            tracker._update_peak_z(np.array([0]), z)
            out.append(tracker._reportable(t))
        return out

    bright, faint, dark = [20.0] * 30, [13.0] * 15, [5.0] * 10
    first = 16  # 20·(1 − 0.9^(f + 1)) ≥ 16 from f = 15 on
    proven = reported(5, 12.0, bright + faint + dark)
    assert not any(proven[:first - 1]) and all(proven[first:30])
    assert all(proven[30:30 + 8]) and not any(proven[-5:])  # the running peak falls from ≈ 19.3 to 13, then below 12
    plain = reported(5, 0.0, bright + faint + dark)
    assert plain[:30] == proven[:30] and not all(plain[30:38])  # the plain gate cuts it as it falls below 16
    unproven = reported(100, 12.0, bright + faint + dark)  # never reported in 100 frames: the plain gate
    assert unproven == plain
    with pytest.raises(tbd.ParameterError, match="keep_peak_z"):
        SGDSPF((20, 20), keep_peak_z=-1.0)


def test_still_frames_keeps_a_still_track_that_goes_early_out_of_the_whole_paths():
    """still_frames 30 (radius 3 px) under min_peak_z 16 at peak z 20 (reported from frame 15 on): a still track
    joins the whole paths at its 30th reported frame, a track moving 0.25 px/frame once it is 3 px from where it
    was first reported (frame 28), a still track where a track of the whole paths ended at once; online rows
    are the same in every case, and still_frames 0 (the paper profile) puts every reported track in at once."""
    from tbd_taichi.methods.sgds.confirmation import Track

    def joins(still_frames: int, speed: float = 0.0, ended_at=None, frames: int = 60):
        tracker = SGDSPF((40, 40), min_peak_z=16.0, still_frames=still_frames)
        if ended_at is not None:
            old = Track(1, 0, confirmed=True, reported=True, whole=True, reported_span=(0, 0),
                        path=deque([(0, *ended_at, 0, 0, 1, 1)]))
            tracker.active.append(old)
            tracker._end_track(old)
        t, online, whole = Track(2, 1, confirmed=True, path=deque()), [], []
        for f in range(frames):
            x = 10.0 + speed * f
            z = np.zeros((40, 40), np.float32)
            z[10, int(round(x))] = 20.0
            t.path.append((f, x, 10.0, speed, 0, 1, 1))
            tracker.states.xy[1] = (x, 10.0)
            tracker._update_peak_z(np.array([1]), z)
            online.append(tracker._reportable(t))
            whole.append(t.whole)
        tracker.active.append(t)  # the whole paths hold its rows from its first reported frame, or none
        rows = tracker.whole_paths()
        assert rows["frame"][rows["track_id"] == 2].tolist() == (list(range(online.index(True), frames)) if t.whole else [])
        return online, whole

    online, whole = joins(0)
    first = online.index(True)
    assert first == 15 and all(online[first:]) and whole == online
    online30, whole30 = joins(30)
    assert online30 == online and whole30.index(True) == first + 29 and all(whole30[first + 29:])
    assert not any(joins(30, frames=first + 29)[1])  # gone after 29 reported frames: never in the whole paths
    moving_online, moving = joins(30, speed=0.25)
    assert moving_online == online and moving.index(True) == 28  # 0.25·(28 − 15) = 3.25 px > 3 px
    assert joins(30, ended_at=(11.0, 12.0))[1].index(True) == first  # 2.2 px from a whole-path track's end
    assert joins(30, ended_at=(14.0, 10.0))[1].index(True) == first + 29  # 4 px away: a new place
    with pytest.raises(tbd.ParameterError, match="still_radius"):
        SGDSPF((20, 20), still_radius=-1.0)


def test_near_any_of_agrees_with_near_any_point_by_point(rng):
    """The vectorised duplicate test gives near_any's answer at every position, with points exactly at,
    just inside and just outside the radius, and for no points or no positions."""
    from tbd_taichi.methods.sgds.confirmation import DUPLICATE_RADIUS, near_any, near_any_of

    points = [(10.0, 10.0)] + [(float(x), float(y)) for x, y in rng.uniform(0, 20, (30, 2))
                               if math.hypot(x - 10, y - 10) > 2 * DUPLICATE_RADIUS][:6]
    x, y = rng.uniform(-2, 22, 400), rng.uniform(-2, 22, 400)
    edge = 10.0 + DUPLICATE_RADIUS  # on a horizontal line through the first point: at, inside, outside
    x = np.concatenate([x, [edge, np.nextafter(edge, 0), np.nextafter(edge, 2 * edge)]])
    y = np.concatenate([y, np.full(3, points[0][1])])
    got = near_any_of(points, x, y)
    want = np.array([near_any(points, a, b) for a, b in zip(x.tolist(), y.tolist())])
    np.testing.assert_array_equal(got, want)
    assert 0 < want.sum() < len(want) and want[-3:].tolist() == [False, True, False]
    assert near_any_of([], x, y).tolist() == [False] * len(x)
    assert near_any_of(points, x[:0], y[:0]).shape == (0,)


def test_merge_duplicates_ends_the_younger_of_close_tracks():
    """Tracks 1–2 are 1.9 px apart (2 ends), 3–4 exactly 2 px (both stay), 5–6–7 each 1.5 px from the next:
    5 ends 6, and 7 (1.5 px from the ended 6, 3 px from 5) stays; the ended tracks' groups are freed."""
    from tbd_taichi.methods.sgds.confirmation import Track

    tracker = SGDSPF((40, 40), snr=2.0, engine="numpy")
    places = {1: (5.0, 5.0), 2: (6.9, 5.0), 3: (20.0, 5.0), 4: (20.0, 7.0), 5: (5.0, 20.0), 6: (6.5, 20.0),
              7: (8.0, 20.0)}
    tracker.active = [Track(k, k, path=deque([(0, x, y, 0.0, 0.0, 1.0, 1.0)])) for k, (x, y) in places.items()]
    for k, (x, y) in places.items():
        tracker.states.start(k, 0, x, y)
    tracker.free_groups, tracker.ended_groups = [], []
    tracker._merge_duplicates()
    assert [t.track_id for t in tracker.active] == [1, 3, 4, 5, 7]
    assert sorted(tracker.free_groups) == [2, 6] and sorted(tracker.ended_groups) == [2, 6]
    tracker.active = tracker.active[:1]
    tracker._merge_duplicates()  # one track: nothing to compare
    assert [t.track_id for t in tracker.active] == [1]
