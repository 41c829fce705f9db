"""SGDS-PF's multi-frame hand-over (tbd_taichi/methods/sgds/handover.py): the retrodicted likelihood sum, the
draw it drives, and its place in the tracker (Algorithm 2's uniform draw with handover_frames = 0)."""
import numpy as np
import pytest

import tbd_taichi
from tbd_taichi.kernels import handover as taichi_handover
from tbd_taichi.methods.sgds import handover
from tbd_taichi.methods.sgds.params import SGDSParams
from tbd_taichi.numpy_kernels import handover as numpy_handover
from tbd_taichi.methods.sgds.populations import resize_population
from tbd_taichi.kernels.models.likelihood import PAD
from tbd_taichi.numpy_kernels.models import point_psf_log_ratio, psf_constants

PSF, SHAPE = 0.7, (40, 48)
CONSTANTS = psf_constants(PSF, 1.0)
SIGMAS = (PSF, 1.0)


@pytest.fixture(autouse=True)
def cpu():
    tbd_taichi.init("cpu")


def ring(frames: dict, k: int = 8) -> handover.RecentFrames:
    """A RecentFrames of SHAPE holding {frame: z}."""
    recent = handover.RecentFrames(k, SHAPE)
    for f in sorted(frames):
        recent.add(f, frames[f])
    return recent


def spot(x: float, y: float, intensity: float) -> np.ndarray:
    """Eq. 14's point target (sampled Gaussian PSF, volume ``intensity``) on a zero frame."""
    yy, xx = np.mgrid[:SHAPE[0], :SHAPE[1]]
    return (intensity / (2 * np.pi * PSF ** 2) * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * PSF ** 2))).astype(
        np.float32)


def pp(n: int, **columns) -> dict:
    """A PP of n particles: x, y, vx, vy, inten (float32) and e (1 unless given)."""
    out = {k: np.full(n, columns.get(k, 0.0), np.float32) for k in ("x", "y", "vx", "vy", "inten")}
    out["e"] = np.asarray(columns.get("e", np.ones(n)), np.int32)
    for k, v in columns.items():
        if k != "e":
            out[k] = np.asarray(np.broadcast_to(v, n), np.float32).copy()
    return out


def test_recent_frames_keep_the_k_frames_before_in_a_bordered_ring():
    recent = handover.RecentFrames(3, SHAPE)
    frames = [np.full(SHAPE, f, np.float32) for f in range(6)]
    for f, z in enumerate(frames):
        recent.add(f, z)
    frames[4][...] = -1  # the caller reuses its buffer: the stored frame keeps its values
    back, slots = recent.before(5)
    assert back.tolist() == [3, 2, 1] and slots.tolist() == [2, 3, 0]  # frames 2, 3, 4 in slots f mod 4
    rows = SHAPE[0] + 2 * PAD
    for j, slot in zip(back, slots):
        bordered = recent.frames[slot * rows:(slot + 1) * rows]
        assert np.all(bordered[PAD:-PAD, PAD:-PAD] == 5 - j) and not bordered[:PAD].any() and not bordered[:, -PAD:].any()
    assert recent.before(4)[0].tolist() == [2, 1] and recent.before(9)[0].tolist() == []  # frame 1 is gone
    assert handover.RecentFrames(0, SHAPE).before(1)[0].tolist() == []


KERNELS = pytest.mark.parametrize("kernels", [taichi_handover, numpy_handover], ids=["taichi", "numpy"])


def sums(kernels, members: dict, recent, frame: int) -> np.ndarray:
    """The retrodicted sums s_i of every member (one PP, all E = 1), from the kernel's ``scores[0]``."""
    n = len(members["x"])
    state = np.stack([members[k] for k in ("x", "y", "vx", "vy", "inten")] + [np.ones(n, np.float32)])
    back, slots = recent.before(frame)
    scores = np.zeros((2, n))
    kernels.multi_frame_draws(state, np.array([[0], [n], [0]], np.int32), recent.frames,
                              np.stack([back, slots.astype(np.float32)]), np.array([*CONSTANTS, recent.shape[0], 4, 0.5]),
                              np.zeros(4, np.int32), scores)
    return scores[0]


@KERNELS
def test_the_sum_takes_each_particle_back_along_its_own_velocity(kernels):
    """s = Σ_j Eq. 15 at (x − j·vx, y − j·vy) on z_{f−j}: a particle whose velocity leads back to the spots
    scores each spot's log ratio; one with the opposite velocity scores what its wrong positions give."""
    x, y, vx, vy, inten = 20.3, 15.6, 0.7, -0.4, 6.0
    spots = {10 - j: spot(x - j * vx, y - j * vy, inten) for j in (3, 2, 1)}
    s = sums(kernels, pp(2, x=x, y=y, vx=[vx, -vx], vy=[vy, -vy], inten=inten), ring(spots), 10)
    for k, sign in enumerate((1, -1)):
        expected = sum(float(point_psf_log_ratio(np.float32([x - j * sign * vx]), np.float32([y - j * sign * vy]),
                                                 np.float32([inten]), spots[10 - j], CONSTANTS)[0]) for j in (3, 2, 1))
        assert s[k] == pytest.approx(expected, rel=1e-5)
    assert s[0] > s[1] + 10  # on the spots vs beside them
    assert np.all(sums(kernels, pp(3), ring({}), 10) == 0)


@pytest.mark.parametrize("shape", [(9, 11), (40, 48)])
def test_kernel_matches_twin_on_random_particles_at_borders_and_beyond(rng, shape):
    """Random particles over and around odd-sized frames (windows cut by every border, some wholly outside), random
    velocities, intensities and E, five PPs of uneven sizes (one without E = 1, one of a single particle) with
    jitter, a ring that has wrapped: the kernel's sums and draws against its NumPy twin's (f32 ratios: a few ulps
    of the sums; the jitter is the host's, the same for both)."""
    recent = handover.RecentFrames(5, shape)
    for f in range(9):
        recent.add(f, (rng.standard_normal(shape) * 3).astype(np.float32))
    n = 3000
    members = pp(n, x=rng.uniform(-6, shape[1] + 5, n), y=rng.uniform(-6, shape[0] + 5, n),
                 vx=rng.normal(0, 1.5, n), vy=rng.normal(0, 1.5, n), inten=rng.uniform(0, 8, n),
                 e=rng.random(n) < 0.7)
    members["e"][2000:2100] = 0
    pps = [(0, 700), (900, 1), (1000, 1000), (2000, 100), (2200, 800)]
    np.testing.assert_allclose(sums(taichi_handover, members, recent, 8), sums(numpy_handover, members, recent, 8),
                               rtol=1e-5, atol=1e-4)
    got = handover.multi_frame_draws(taichi_handover, {k: v.copy() for k, v in members.items()}, pps, 333, recent, 8,
                                     SIGMAS, [np.random.default_rng(k) for k in range(5)], 0.3)
    want = handover.multi_frame_draws(numpy_handover, {k: v.copy() for k, v in members.items()}, pps, 333, recent, 8,
                                      SIGMAS, [np.random.default_rng(k) for k in range(5)], 0.3)
    same = np.mean([np.mean(a == b) for a, b in zip(got, want)])
    assert same > 0.99, same  # the cumulative weights' f64 exponentials may differ by an ulp at a boundary
    for (start, size), picks in zip(pps, got):
        assert np.all((picks >= start) & (picks < start + size)) and np.all(np.diff(picks) >= 0)
        assert members["e"][picks].all() or start == 2000  # E = 1 only, but where the PP has none


@KERNELS
def test_the_kernel_draw_is_the_host_systematic_draw(rng, kernels):
    """Member i takes the draws whose point (u + j)/size falls in its share of the cumulative weights: the kernel's
    counts ⌈c_i/c·size − u⌉ give the picks of NumPy's searchsorted on the normalised cumulative weights."""
    recent = ring({f: rng.standard_normal(SHAPE).astype(np.float32) for f in range(4, 12)})
    members = pp(500, x=rng.uniform(0, 48, 500), y=rng.uniform(0, 40, 500), vx=rng.normal(0, 1, 500),
                 vy=rng.normal(0, 1, 500), inten=rng.uniform(1, 4, 500))
    for size in (1, 7, 499, 2000):
        picks, = handover.multi_frame_draws(kernels, members, [(0, 500)], size, recent, 12, SIGMAS,
                                            [np.random.default_rng(size)])
        s = sums(kernels, members, recent, 12)
        w = np.exp(s - s.max())
        u = np.random.default_rng(size).random()
        want = np.minimum(np.searchsorted(np.cumsum(w / w.sum()), (u + np.arange(size)) / size), 499)
        assert np.array_equal(picks, want)


def test_the_draw_keeps_the_velocity_that_follows_the_target_at_snr_2():
    """Three velocity hypotheses at the target's position after 8 frames of an SNR-2 target on N(0, 1) noise: the
    true one takes (almost) all N_tpf draws; Algorithm 2's uniform draw would give it a third.  Fixed seeds; with
    the true velocity 0.8 px/frame away from the others, 8 frames put the wrong hypotheses 6.4 px off by the end."""
    rng = np.random.default_rng(0)
    x, y, vx, vy = 24.0, 20.0, 0.5, -0.3
    intensity = 2.0 * 2 * np.pi * PSF ** 2  # peak SNR 2
    recent = [spot(x - j * vx, y - j * vy, intensity) + rng.standard_normal(SHAPE).astype(np.float32)
              for j in range(8, 0, -1)]  # frames 2…9, the hand-over at frame 10
    members = pp(300, x=x, y=y, vx=np.repeat([vx, vx + 0.8, vx], 100), vy=np.repeat([vy, vy, vy - 0.8], 100),
                 inten=intensity)
    picks, = handover.multi_frame_draws(taichi_handover, members, [(0, 300)], 500,
                                        ring(dict(zip(range(2, 10), recent))), 10, SIGMAS, [np.random.default_rng(1)])
    assert picks.shape == (500,) and picks.min() >= 0 and picks.max() < 300
    assert np.mean(picks < 100) > 0.95


def test_one_launch_for_several_pps_draws_what_one_launch_each_draws(rng):
    """The PPs of a frame share one launch; each PP's draw is the same as alone (its own generator, its slice)."""
    frames = {f: rng.standard_normal(SHAPE).astype(np.float32) for f in range(3, 12)}
    members = pp(900, x=rng.uniform(0, 48, 900), y=rng.uniform(0, 40, 900), vx=rng.normal(0, 1, 900),
                 vy=rng.normal(0, 1, 900), inten=rng.uniform(1, 4, 900), e=rng.random(900) < 0.6)
    pps = [(0, 300), (300, 250), (550, 350)]
    together = handover.multi_frame_draws(taichi_handover, {k: v.copy() for k, v in members.items()}, pps, 500,
                                          ring(frames), 12, SIGMAS, [np.random.default_rng(k) for k in range(3)], 0.3)
    for k, pp_k in enumerate(pps):
        alone, = handover.multi_frame_draws(taichi_handover, {n: v.copy() for n, v in members.items()}, [pp_k], 500,
                                            ring(frames), 12, SIGMAS, [np.random.default_rng(k)], 0.3)
        assert np.array_equal(together[k], alone)
        assert np.all((alone >= pp_k[0]) & (alone < pp_k[0] + pp_k[1]))


def test_e0_particles_are_drawn_only_where_the_pp_has_no_e1_particle():
    members = pp(10, x=5.0, y=5.0, inten=3.0, e=[0, 1, 0, 1, 1, 0, 0, 0, 1, 0])
    picks, = handover.multi_frame_draws(taichi_handover, members, [(0, 10)], 40, ring({0: np.zeros(SHAPE, np.float32)}),
                                        1, SIGMAS, [np.random.default_rng(2)])
    assert set(picks.tolist()) <= {1, 3, 4, 8}
    none = pp(4, x=5.0, y=5.0, inten=3.0, e=np.zeros(4))
    assert len(handover.multi_frame_draws(taichi_handover, none, [(0, 4)], 8, ring({}), 1, SIGMAS,
                                          [np.random.default_rng(2)])[0]) == 8


def test_with_equal_scores_the_draw_is_systematic_over_the_pp_and_offset_by_its_start():
    """No earlier frame (the first frames of a sequence): every E = 1 particle drawn size/n times exactly."""
    members = pp(25, x=np.arange(25.0), y=3.0, inten=2.0)
    picks, = handover.multi_frame_draws(taichi_handover, members, [(10, 5)], 20, ring({}), 0, SIGMAS,
                                        [np.random.default_rng(3)])
    assert sorted(np.bincount(picks - 10, minlength=5).tolist()) == [4] * 5 and picks.min() == 10


def test_jitter_spreads_the_pp_velocities_in_place():
    members = pp(2000, vx=0.5, vy=-0.5, inten=2.0)
    handover.multi_frame_draws(taichi_handover, members, [(0, 1000)], 10, ring({}), 0, SIGMAS,
                               [np.random.default_rng(4)], jitter=0.3)
    assert np.std(members["vx"][:1000]) == pytest.approx(0.3, rel=0.1)
    assert np.mean(members["vy"][:1000]) == pytest.approx(-0.5, abs=0.03)
    assert np.all(members["vx"][1000:] == 0.5)  # outside the PP: untouched


def test_the_paper_draw_is_kept_with_handover_frames_0():
    """handover_frames = 0 is Algorithm 2's uniform elimination or copying, from the same uniforms."""
    from tbd_taichi.methods.sgds.tracker import SGDSPF

    tracker = SGDSPF((30, 30), snr=2.0, seed=5, engine="numpy", handover_frames=0)
    u = np.random.default_rng(6).random(700)
    got, = tracker._handed_over(3, pp(1000), [(40, 700, u)])
    assert np.array_equal(got, 40 + resize_population(700, tracker.p.N_tpf, u))
    assert SGDSParams().handover_frames == 8 and SGDSParams().handover_jitter == 0.3
    # on in the SNR 1.2 and 1.4 presets, off from 1.6 up (more false tracks at 50×50, SNR 2, no gain there)
    assert [SGDSParams.for_snr(s).handover_frames for s in (1.2, 1.4, 1.59, 1.6, 2.0, 5.0)] == [8, 8, 8, 0, 0, 0]
    assert SGDSParams.for_snr(2.0, handover_frames=5).handover_frames == 5
