"""feature-fusion (Huo et al. 2022): the kernels against their NumPy twin and references (Sobel and Gabor against
cv2.filter2D, histograms, Eqs. 19–22 on identical windows), residual resampling and Eqs. 24–25, and end to end
on a drone-ir clip from its first labelled box."""
from pathlib import Path

import cv2
import numpy as np
import pytest

import tbd_taichi as tbd
from tbd_taichi import io, tables
from tbd_taichi.errors import InputError, ParameterError
from tbd_taichi.kernels import feature_fusion as tk
from tbd_taichi.methods.feature_fusion import new_particles, residual_resample
from tbd_taichi.numpy_kernels import feature_fusion as nk

DATA = Path(__file__).parent / "data"
CLIP, BOXES = DATA / "IR_DRONE_021.mp4", DATA / "IR_DRONE_021.csv"


def make_pools(shape, n=64, bins=8, sigma=1.5, omega=np.pi / 2):
    row, col = tk.gabor_taps(sigma, sigma, omega)
    halves = ((len(row) - 1) // 2, (len(col) - 1) // 2)
    pools = (tk.FeatureFusionKernels(n, shape, bins, halves), nk.FeatureFusionKernels(n, shape, bins, halves))
    for k in pools:
        k.put("row_taps", row)
        k.put("col_taps", col)
    return pools, row, col


def maps(pools, frame):
    out = []
    for k in pools:
        raw = np.zeros((3,) + frame.shape, np.float32)
        k.feature_maps(frame, raw, 1)
        out.append(raw)
    return out


@pytest.mark.parametrize("shape", [(17, 23), (40, 31)])
def test_feature_maps_match_the_twin_and_opencv(rng, shape):
    frame = rng.uniform(0, 255, shape).astype(np.float32)
    pools, row, col = make_pools(shape)
    raw_t, raw_n = maps(pools, frame)
    np.testing.assert_allclose(raw_t, raw_n, rtol=1e-4, atol=1e-3)
    np.testing.assert_array_equal(raw_t[0], frame)
    # Sobel magnitude (Eqs. 14–16) and the Gabor response (Eqs. 17–18) against OpenCV with zero borders
    g2 = np.zeros(shape)
    for kernel in tk.SOBEL:
        g2 += cv2.filter2D(frame.astype(np.float64), -1, np.array(kernel, float), borderType=cv2.BORDER_CONSTANT) ** 2
    inner = (slice(1, -1), slice(1, -1))
    np.testing.assert_allclose(raw_t[1], np.sqrt(g2), rtol=1e-4, atol=1e-2)
    gabor = cv2.filter2D(frame.astype(np.float64), -1, np.outer(col, row).astype(float), borderType=cv2.BORDER_CONSTANT)
    np.testing.assert_allclose(raw_t[2][inner], gabor[inner], rtol=1e-4, atol=1e-2)
    np.testing.assert_allclose(raw_t[2], gabor, rtol=1e-4, atol=1e-2)


def test_feature_maps_after_a_larger_frame_of_the_class_match_fresh_fields(rng):
    """Fields of one size class hold a larger frame first (``backend.reusable`` lends them so): the zero border
    and the row pass's border rows are written again, so the maps of a smaller frame equal those of fields of its
    own and the twin's, borders included."""
    big, small = (61, 57), (17, 23)
    (used, _), _, _ = make_pools(big)
    maps((used,), rng.uniform(200, 255, big).astype(np.float32))  # bright: stale values would show at the borders
    used.set_frame_size(small)
    frame = rng.uniform(0, 255, small).astype(np.float32)
    (fresh, twin), _, _ = make_pools(small)
    raw_used, raw_fresh, raw_twin = maps((used, fresh, twin), frame)
    np.testing.assert_array_equal(raw_used, raw_fresh)
    np.testing.assert_allclose(raw_used, raw_twin, rtol=1e-4, atol=1e-3)


def test_s135_is_the_corrected_kernel():
    """Eq. 14's S_135 bottom row (−2, 1, 0) sums to 2; read (−2, −1, 0): every kernel sums to 0, and S_135 is S_45
    mirrored left to right."""
    assert all(np.array(k).sum() == 0 for k in tk.SOBEL)
    assert tk.SOBEL[3] == ((0, 1, 2), (-1, 0, 1), (-2, -1, 0))
    assert np.array_equal(np.array(tk.SOBEL[3]), np.array(tk.SOBEL[2])[:, ::-1])


def load_pools(pools, frame, state):
    raw = maps(pools, frame)[0]
    lo, hi = np.percentile(raw.reshape(3, -1), (0.5, 99.5), axis=1)
    for k in pools:
        k.put("ranges", np.stack([lo, hi + 1e-3], axis=1))
        k.rebin(raw)
        k.put("state", state)
    return raw


@pytest.mark.parametrize("fusion", ["adaptive", "bin-sum"])
def test_histograms_likelihood_and_fusion_agree_with_the_twin(rng, fusion):
    shape = (33, 41)
    frame = rng.uniform(0, 255, shape).astype(np.float32)
    pools, _, _ = make_pools(shape, n=64)
    state = np.zeros((64, 4), np.float32)
    state[:, 0], state[:, 1] = rng.uniform(-1, 41, 64), rng.uniform(-1, 33, 64)  # some at the borders
    load_pools(pools, frame, state)
    mode = tk.FUSIONS.index(fusion)
    for k in pools:
        k.weigh(0, 1, 3.5, 2.5, 0.15, mode)  # slot 0's histograms become the template
        k.put("template", k.get("hist")[0])
        k.weigh(0, 64, 3.5, 2.5, 0.15, mode)
    if fusion == "bin-sum":  # Eq. 21 as printed: ρ = Σ_b √(F_t F_c), F = Σ_i v_i f_i with the candidate's v
        v, t, hist = pools[0].get("fusion"), pools[0].get("template"), pools[0].get("hist")
        ref = np.sqrt(np.einsum("pf,fb->pb", v, t) * np.einsum("pf,pfb->pb", v, hist)).sum(axis=1)
        np.testing.assert_allclose(pools[0].get("rho"), ref, rtol=1e-5, atol=1e-6)
    for name in ("hist", "rho", "loglik", "fusion", "corr"):
        np.testing.assert_allclose(pools[0].get(name), pools[1].get(name), rtol=1e-4, atol=1e-5, err_msg=name)
    hist = pools[0].get("hist")
    np.testing.assert_allclose(hist.sum(axis=2), 1.0, atol=1e-5)  # Eq. 13 normalises each histogram
    # slot 0 is the template's own window: c_i = 1, v_i = 1/3, ρ = 1, log-likelihood 0
    np.testing.assert_allclose(pools[0].get("corr")[0], 1.0, atol=1e-5)
    np.testing.assert_allclose(pools[0].get("fusion")[0], 1 / 3, atol=1e-5)
    template, corr = pools[0].get("template"), pools[0].get("corr")  # Eq. 19 against NumPy's Pearson
    ref = [[np.corrcoef(template[f], hist[p, f])[0, 1] for f in range(3)] for p in range(1, 64)]
    np.testing.assert_allclose(corr[1:], np.nan_to_num(ref), atol=1e-4)
    assert pools[0].get("rho")[0] == pytest.approx(1.0, abs=1e-5) and pools[0].get("loglik")[0] == pytest.approx(0, abs=1e-3)
    assert np.all(pools[0].get("rho") <= 1 + 1e-5)


@pytest.mark.parametrize("velocity", [0, 1])
def test_one_launch_step_is_the_twins_serial_or_parallel(rng, velocity):
    """``step`` (Eq. 1, Eqs. 11–22, Eqs. 10, 6, 23, then the estimate weighed) gives the twin's state, weights and
    (x̂, ŷ, N_eff, ρ) in its serial and its parallel form, for three frames in a row."""
    shape, n = (33, 41), 65  # 64 particles and the estimate's slot
    frame = rng.uniform(0, 255, shape).astype(np.float32)
    pools, _, _ = make_pools(shape, n=n)
    state = np.zeros((n, 4), np.float32)
    state[:, 0], state[:, 1] = rng.uniform(0, 40, n), rng.uniform(0, 32, n)
    load_pools(pools, frame, state)
    pools[0].weigh(0, 1, 3.5, 2.5, 0.15, 1)
    template = pools[0].get("hist")[0]
    outs = []
    for k, serial in ((pools[0], True), (pools[0], False), (pools[1], False)):
        k.put("template", template)
        k.put("state", state)
        k.put("logw", np.zeros(n))
        k.configure(2.0, velocity, 3.5, 2.5, 0.15, 1)
        out = np.zeros(4)
        for f in (1, 2, 3):
            k.step(7, f, out, serial)
        outs.append((k.get("state"), k.get("logw"), out.copy()))
    for got in outs[1:]:
        for a, b, name in zip(outs[0], got, ("state", "logw", "out")):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5, err_msg=name)
    assert 1 <= outs[0][2][2] <= n - 1 and 0 < outs[0][2][3] <= 1 + 1e-5  # N_eff, ρ at the estimate
    assert tk.histogram_work(200, 4.5, 4.5) <= tk.SERIAL_WORK < tk.histogram_work(2000, 4.5, 4.5)


def test_histogram_by_hand_on_a_tiny_window():
    """A 3×3 window (half 1.5 × 1.5, s² = 4.5) on a two-level image: k = 1 − r²/s² per pixel, normalised."""
    shape = (9, 9)
    frame = np.zeros(shape, np.float32)
    frame[4, 5] = 100.0  # the pixel right of the centre is bright
    pools, _, _ = make_pools(shape, n=1, bins=2)
    for k in pools:
        k.put("ranges", np.array([[0, 100], [0, 1e6], [-1e6, 1e6]], np.float32))
        raw = np.zeros((3,) + shape, np.float32)
        k.feature_maps(frame, raw, 1)
        k.put("state", np.array([[4.0, 4.0, 0, 0]], np.float32))
        k.weigh(0, 1, 1.5, 1.5, 0.15, 0)
        weights = {(dr, dc): 1 - (dr * dr + dc * dc) / 4.5 for dr in (-1, 0, 1) for dc in (-1, 0, 1)}
        bright = weights[(0, 1)] / sum(weights.values())
        np.testing.assert_allclose(k.get("hist")[0, 0], [1 - bright, bright], atol=1e-6)


def test_residual_resampling_keeps_n_and_expected_counts(rng):
    w = np.array([0.31, 0.29, 0.2, 0.1, 0.05, 0.05])
    parents = residual_resample(w, rng.random(6))
    assert len(parents) == 6
    counts = np.bincount(parents, minlength=6)
    assert np.all(counts >= np.floor(6 * w)) and np.all(counts <= np.floor(6 * w) + 6)
    assert np.all(np.diff(w[parents]) <= 0)  # sorted by parent weight, highest first
    total = np.zeros(6)
    for i in range(4000):
        total += np.bincount(residual_resample(w, rng.random(6)), minlength=6)
    np.testing.assert_allclose(total / 4000, 6 * w, atol=0.05)  # E[count_i] = N·w_i


def test_new_particles_are_the_eight_neighbours_closest_to_the_last_estimate():
    best = np.array([[10.0, 10.0], [10.0, 10.0], [20.0, 20.0]])
    pts = new_particles(best, np.array([0.0, 0.0]), 2.0, 5)
    assert len(pts) == 5 and len(np.unique(pts, axis=0)) == 5  # duplicates of the repeated parent removed
    assert [8.0, 8.0] in pts.tolist() and all(p[0] <= 12 for p in pts)
    assert len(new_particles(best[:1], np.zeros(2), 2.0, 100)) == 8  # fewer candidates than asked: all of them


@pytest.fixture(scope="module")
def clip():
    frames = io.read_frames(CLIP)[:60]
    boxes = tables.read_boxes(BOXES)
    return frames, boxes


def test_drone_clip_is_followed_from_its_first_box(clip):
    """60 frames of IR_DRONE_021 from its first labelled box: every frame within 10 px of the labelled centre,
    most within 5 px; the rows carry the box size."""
    frames, boxes = clip
    b = boxes[0]
    tracks = tbd.track(frames, method="feature-fusion", init_box=(b["x"], b["y"], b["w"], b["h"]), seed=0)
    assert len(tracks) == 60 and set(tracks.dtype.names) >= {"w", "h"}
    truth = {int(r["frame"]): (r["x"] + r["w"] / 2, r["y"] + r["h"] / 2) for r in boxes}
    err = np.array([np.hypot(t["x"] - truth[int(t["frame"])][0], t["y"] - truth[int(t["frame"])][1])
                    for t in tracks if int(t["frame"]) in truth])
    assert err.max() < 10 and np.mean(err < 5) > 0.8, err
    assert tracks["w"][0] == b["w"] and np.all((tracks["confidence"] > 0) & (tracks["confidence"] <= 1.0001))


def test_engines_follow_the_same_target(clip):
    frames, boxes = clip
    b = boxes[0]
    out = [tbd.track(frames[:20], method="feature-fusion", init_box=(b["x"], b["y"], b["w"], b["h"]), engine=e)
           for e in ("taichi", "numpy")]
    assert np.max(np.hypot(out[0]["x"] - out[1]["x"], out[0]["y"] - out[1]["y"])) < 1.0


@pytest.mark.parametrize("settings", [{"grey_range": "8-bit"}, {"fusion": "bin-sum"}])
def test_the_alternatives_run_on_both_engines(clip, settings):
    """The ambiguities' alternatives kept as parameters: the grey bins over [0, 256) and Eq. 21's bin-wise sum."""
    from tbd_taichi.methods.feature_fusion import EIGHT_BIT, FeatureFusionTracker

    frames, boxes = clip
    b = boxes[0]
    out = []
    for engine in ("taichi", "numpy"):
        tracker = FeatureFusionTracker(frames.shape[1:], (b["x"], b["y"], b["w"], b["h"]), engine=engine, **settings)
        for frame in frames[:20]:
            tracker.update(frame)
        out.append(tracker.finish())
        if "grey_range" in settings:
            assert tuple(tracker.k.get("ranges")[0]) == EIGHT_BIT
    assert len(out[0]) == 20 and np.max(np.hypot(out[0]["x"] - out[1]["x"], out[0]["y"] - out[1]["y"])) < 1.0
    last = boxes[boxes["frame"] == 19][0]
    assert np.hypot(out[0]["x"][-1] - (last["x"] + last["w"] / 2), out[0]["y"][-1] - (last["y"] + last["h"] / 2)) < 10


@pytest.mark.slow
def test_same_csv_with_one_and_two_threads(csv_by_threads, clip):
    frames, boxes = clip
    b = boxes[0]
    outs = csv_by_threads(frames[:30], "--method", "feature-fusion", "--init-box", f"{b['x']},{b['y']},{b['w']},{b['h']}")
    assert outs[0] == outs[1] and outs[0].count(b"\n") == 31


@pytest.mark.parametrize("box, error, offender", [
    (None, ParameterError, "--init-box"),
    ((1, 2, 3), ParameterError, "four numbers"),
    ((1, 2, np.nan, 4), ParameterError, "finite"),
    ((1, 2, 0, 4), ParameterError, "W, H > 0"),
    ((500, 2, 5, 5), ParameterError, "outside"),
])
def test_bad_boxes_are_refused(box, error, offender):
    with pytest.raises(error, match=offender):
        tbd.make_tracker("feature-fusion", (64, 64), init_box=box)


def test_a_box_partly_outside_is_clipped_with_a_warning():
    tracker = tbd.make_tracker("feature-fusion", (64, 64), init_box=(-4, 10, 10, 8))
    with pytest.warns(UserWarning, match="clipped"):
        tracker.update(np.zeros((64, 64), np.float32))


def test_a_frame_of_another_shape_and_a_single_frame_are_refused():
    tracker = tbd.make_tracker("feature-fusion", (64, 64), init_box=(10, 10, 8, 8))
    tracker.update(np.zeros((64, 64), np.float32))
    with pytest.raises(InputError, match="frame 1"):
        tracker.update(np.zeros((60, 64), np.float32))
    with pytest.raises(InputError):
        tbd.track(np.zeros((1, 64, 64), np.float32), method="feature-fusion", init_box=(10, 10, 8, 8))
