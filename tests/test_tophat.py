"""tophat-pf candidate stage (Güler 2016, §3.4.1): the top-hat kernel against its NumPy twin and OpenCV
(Eqs. 3.4–3.10, out-of-image pixels ignored), the SE masks against OpenCV's, and projection (Eq. 3.12),
threshold (Eq. 3.13) and 8-connected candidates by hand and against scipy."""
import cv2
import numpy as np
import pytest
from scipy import ndimage

from tbd_taichi import tophat as host
from tbd_taichi.errors import InputError, ParameterError
from tbd_taichi.kernels import tophat as tk
from tbd_taichi.numpy_kernels import tophat as nk

CV_SHAPES = {"square": cv2.MORPH_RECT, "disk": cv2.MORPH_ELLIPSE}
PEAK = 100.0  # the 1-px peaks' height over a background uniform in [0, 10)


def cv2_tophat(frame: np.ndarray, se_size: int, se_shape: str) -> np.ndarray:
    """OpenCV's opening top-hat (default border: out-of-image pixels ignored) of the row-mean-removed f32 image."""
    u = frame - frame.mean(axis=1, dtype=np.float64).astype(np.float32)[:, None]
    se = cv2.getStructuringElement(CV_SHAPES[se_shape], (se_size, se_size))
    return cv2.morphologyEx(u, cv2.MORPH_TOPHAT, se)


def frame_with_peaks(rng, shape) -> tuple[np.ndarray, list]:
    """A random f32 frame with 1-px peaks at the four corners and the middle of each edge; the peak pixels."""
    h, w = shape
    frame = rng.uniform(0, 10, shape).astype(np.float32)
    peaks = [(0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1), (0, w // 2), (h - 1, w // 2), (h // 2, 0), (h // 2, w - 1)]
    for r, c in peaks:
        frame[r, c] += PEAK
    return frame, peaks


def run(module, frame, se_size, se_shape) -> np.ndarray:
    out = np.zeros(frame.shape, np.float32)
    module.TophatKernels(frame.shape, se_size, se_shape).tophat(frame, out)
    return out


# ------------------------------------------------------------------ structuring elements


@pytest.mark.parametrize("se_shape", ["square", "disk"])
@pytest.mark.parametrize("size", range(3, 16, 2))
def test_structuring_element_is_opencvs(size, se_shape):
    mask = tk.structuring_element(size, se_shape)
    assert mask.dtype == np.uint8
    np.testing.assert_array_equal(mask, cv2.getStructuringElement(CV_SHAPES[se_shape], (size, size)))
    assert nk.structuring_element is tk.structuring_element


@pytest.mark.parametrize("size", range(3, 42, 2))
def test_every_ellipse_row_is_a_centred_run(size):
    """What the separable passes rely on: row i of the mask is exactly |j − c| ≤ half[i] (no raise), and the SE is
    symmetric (so the dilation's reflected SE is the SE)."""
    mask = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    half = tk.row_half_widths(mask)
    c = size // 2
    np.testing.assert_array_equal(np.abs(np.arange(size)[None, :] - c) <= half[:, None], mask.astype(bool))
    np.testing.assert_array_equal(mask, mask[::-1, ::-1])


def test_a_mask_with_an_off_centre_row_is_refused():
    mask = np.ones((3, 3), np.uint8)
    mask[0] = (1, 1, 0)
    with pytest.raises(ParameterError, match="row 0"):
        tk.row_half_widths(mask)


# ------------------------------------------------------------------ the top-hat: Taichi vs NumPy vs OpenCV


@pytest.mark.parametrize("se_shape", ["square", "disk"])
@pytest.mark.parametrize("shape, se_size", [(shape, size) for shape in [(7, 9), (31, 17), (100, 100)]
                                            for size in (3, 5, 7, 9) if size <= min(shape)])
def test_tophat_matches_the_twin_and_opencv(rng, shape, se_size, se_shape):
    frame, peaks = frame_with_peaks(rng, shape)
    taichi_out, numpy_out = run(tk, frame, se_size, se_shape), run(nk, frame, se_size, se_shape)
    reference = cv2_tophat(frame, se_size, se_shape)
    # f32 throughout: min/max and the final difference are exact, and the row means are summed in f64 and rounded to
    # f32 on every side, so the three normally agree bit for bit; a different summation order (another backend) may
    # move a row mean by an ulp of the image scale (~1e-5 of 110), far inside atol = 1e-3 of the scale.
    atol = 1e-3 * float(np.abs(frame).max())
    np.testing.assert_allclose(taichi_out, numpy_out, rtol=0, atol=atol)
    np.testing.assert_allclose(taichi_out, reference, rtol=0, atol=atol)
    np.testing.assert_allclose(numpy_out, reference, rtol=0, atol=atol)
    # a 1-px peak on the border survives whole (out-of-image pixels are ignored, not reflected into a 2-px blob);
    # its row's mean rises by PEAK·(≤ 3)/W, the background varies by < 10
    floor = PEAK - 10 - 3 * PEAK / shape[1]
    assert all(taichi_out[r, c] > floor for r, c in peaks)
    assert (taichi_out >= 0).all()  # the opening is anti-extensive


def test_any_odd_size_works_and_a_kernel_is_reusable(rng):
    """Dynamic SE loops: 15 and 17 on a 31 × 17 frame; the same instance on two frames (fields reused)."""
    for se_size in (15, 17):
        kernels = tk.TophatKernels((31, 17), se_size, "disk")
        for _ in range(2):
            frame, _ = frame_with_peaks(rng, (31, 17))
            out = np.zeros_like(frame)
            kernels.tophat(frame, out)
            np.testing.assert_allclose(out, cv2_tophat(frame, se_size, "disk"), rtol=0, atol=1e-3 * PEAK)
            np.testing.assert_allclose(out, run(nk, frame, se_size, "disk"), rtol=0, atol=1e-3 * PEAK)


def test_row_means_are_removed_first():
    """A frame constant along each row (a pure row-wise temperature gradient, Eqs. 3.4–3.5) top-hats to zero."""
    frame = np.repeat(np.linspace(7000, 7200, 12, dtype=np.float32)[:, None], 15, axis=1)
    for module in (tk, nk):
        np.testing.assert_array_equal(run(module, frame, 5, "square"), 0)


# ------------------------------------------------------------------ projection, threshold, candidates by hand


def test_projection_and_threshold_by_hand():
    """P = ±1 in a checkerboard (mean 0, std 1); D = (P, 2P, 3P) has σ = (1, 2, 3), so I_c = 3P (Eq. 3.12);
    μ(I_c) = 0, σ(I_c) = 3, so T = 0.5·3 = 1.5 for α = 0.5 (Eq. 3.13)."""
    p = np.where((np.arange(4)[:, None] + np.arange(6)[None, :]) % 2 == 0, 1.0, -1.0)
    ic = host.projection(np.stack([p, 2 * p, 3 * p]).astype(np.float32))
    assert ic.dtype == np.float64 and ic.shape == (4, 6)
    np.testing.assert_allclose(ic, 3 * p, rtol=1e-12)
    assert host.threshold(ic, 0.5) == pytest.approx(1.5)
    assert host.threshold(ic, -1.0) == pytest.approx(-3.0)


def test_a_constant_tophat_is_refused():
    d = np.ones((3, 5, 5))
    d[0, 2, 2] = d[2, 1, 1] = 5.0
    with pytest.raises(ParameterError, match="frame 1 is constant after the top-hat"):
        host.projection(d)


def hand_ic() -> np.ndarray:
    """Above T = 2: a 2-px blob (max 7 at row 1, col 2), a diagonal pair (6 at (4, 4), 9 at (5, 5)) that
    8-connectivity joins, a lone 3 at (0, 7), a lone 7 at (6, 0) tying the blob; a 2 (= T, not above) at (3, 0)."""
    ic = np.zeros((7, 8))
    ic[1, 1], ic[1, 2] = 5.0, 7.0
    ic[4, 4], ic[5, 5] = 6.0, 9.0
    ic[0, 7], ic[6, 0], ic[3, 0] = 3.0, 7.0, 2.0
    return ic


def test_candidates_by_hand():
    got = host.candidates(hand_ic(), 2.0, 10)
    assert got.dtype == np.float64 and got.shape == (4, 3)
    # [x = column, y = row, score]: strongest first, the two 7s by row
    np.testing.assert_array_equal(got, [[5, 5, 9], [2, 1, 7], [0, 6, 7], [7, 0, 3]])
    # 4-connectivity would split the diagonal pair: 8-connectivity is what joins it
    assert ndimage.label(hand_ic() > 2.0)[1] == 5


def test_the_cap_keeps_the_strongest():
    np.testing.assert_array_equal(host.candidates(hand_ic(), 2.0, 2), [[5, 5, 9], [2, 1, 7]])
    np.testing.assert_array_equal(host.candidates(hand_ic(), 2.0, 1), [[5, 5, 9]])
    assert host.candidates(hand_ic(), 9.0, 5).shape == (0, 3)


def test_a_tie_inside_a_component_takes_the_first_pixel_in_row_order():
    ic = np.zeros((4, 4))
    ic[1, 2] = ic[2, 1] = 4.0  # one component (diagonal), two equal maxima
    np.testing.assert_array_equal(host.candidates(ic, 1.0, 3), [[2, 1, 4]])


def test_candidates_match_scipy_components(rng):
    """Random I_c: one candidate per scipy 8-connected label, at its row-major-first maximum."""
    ic = ndimage.gaussian_filter(rng.normal(size=(60, 50)), 1.0)
    thr = host.threshold(ic, 1.0)
    labels, n = ndimage.label(ic > thr, structure=np.ones((3, 3)))
    assert n > 5
    expected = []
    for k in range(1, n + 1):
        masked = np.where(labels == k, ic, -np.inf)
        r, c = np.unravel_index(np.argmax(masked), ic.shape)
        expected.append((c, r, ic[r, c]))
    expected.sort(key=lambda e: (-e[2], e[1], e[0]))
    np.testing.assert_array_equal(host.candidates(ic, thr, n), np.array(expected))
    np.testing.assert_array_equal(host.candidates(ic, thr, 3), np.array(expected[:3]))


# ------------------------------------------------------------------ the whole stage


def scene(rng, shape=(40, 50)) -> np.ndarray:
    """3 frames: a row-wise temperature gradient, noise σ = 2 counts and a 1-px target of +60 moving along row 20
    from column 0 (1 px a frame)."""
    h, w = shape
    gradient = np.linspace(7000, 7400, h)[:, None] + 0.5 * np.arange(w)[None, :]
    frames = gradient[None] + rng.normal(0, 2.0, (3, h, w))
    for k in range(3):
        frames[k, 20, k] += 60.0
    return frames


@pytest.mark.parametrize("se_shape", ["square", "disk"])
def test_find_candidates_on_both_engines(rng, se_shape):
    frames = scene(rng)
    got_t, ic_t, thr_t = host.find_candidates(frames, 3.0, 5, se_shape, 8, engine="taichi")
    got_n, ic_n, thr_n = host.find_candidates(frames, 3.0, 5, se_shape, 8, engine="numpy")
    np.testing.assert_allclose(ic_t, ic_n, rtol=1e-6, atol=1e-6)  # same f32 top-hats: see the tolerance note above
    assert thr_t == pytest.approx(thr_n)
    np.testing.assert_array_equal(got_t[:, :2], got_n[:, :2])
    assert 1 <= len(got_t) <= 8
    assert got_t[0, 1] == 20 and got_t[0, 0] <= 2  # the target's smear is the strongest candidate
    d = np.stack([cv2_tophat(f.astype(np.float32), 5, se_shape) for f in frames])
    np.testing.assert_allclose(ic_t, host.projection(d), rtol=1e-5, atol=1e-5)
    assert thr_t == pytest.approx(host.threshold(ic_t, 3.0))


# ------------------------------------------------------------------ bad parameters


@pytest.mark.parametrize("se_size", [4, 2, 1, -3, 0, 3.0, "5", True, None, 41])
def test_a_bad_se_size_is_refused(se_size):
    with pytest.raises(ParameterError, match="se_size") as err:
        host.check_structuring_element(se_size, "square", (40, 50))
    assert "\n" not in str(err.value)
    with pytest.raises(ParameterError, match="se_size"):
        host.find_candidates(np.ones((3, 40, 50)), 3.0, se_size, "square", 8, engine="numpy")


@pytest.mark.parametrize("se_shape", ["circle", "Square", None, ""])
def test_a_bad_se_shape_is_refused(se_shape):
    with pytest.raises(ParameterError, match="se_shape") as err:
        host.check_structuring_element(5, se_shape, (40, 50))
    assert "\n" not in str(err.value) and "square" in str(err.value) and "disk" in str(err.value)
    with pytest.raises(ParameterError, match="se_shape"):
        tk.structuring_element(5, se_shape)


def test_good_structuring_elements_pass():
    for se_size in (3, 5, np.int64(7), 39):
        host.check_structuring_element(se_size, "disk", (39, 50))


def test_other_bad_inputs_are_refused(rng):
    with pytest.raises(ParameterError, match="max_candidates"):
        host.candidates(hand_ic(), 2.0, 0)
    with pytest.raises(ParameterError, match="alpha"):
        host.threshold(hand_ic(), float("nan"))
    with pytest.raises(InputError, match="first 3 frames"):
        host.find_candidates(np.ones((2, 10, 10)), 3.0, 3, "square", 8, engine="numpy")
    with pytest.raises(InputError, match="finite"):
        host.find_candidates(np.full((3, 10, 10), np.nan), 3.0, 3, "square", 8, engine="numpy")
