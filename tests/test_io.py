"""Frame input: every supported source, and a clear error for every bad one."""
import types

import cv2
import numpy as np
import pytest

from tbd_taichi import io
from tbd_taichi.errors import InputError


@pytest.fixture
def seq(rng):
    return rng.integers(0, 255, size=(6, 17, 23)).astype(np.uint8)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16, np.int32, np.float32, np.float64])
def test_npy_any_real_dtype(tmp_path, seq, dtype):
    data = (seq.astype(np.int64) * (200 if dtype == np.uint16 else 1)).astype(dtype)
    np.save(tmp_path / "a.npy", data)
    out = io.read_frames(tmp_path / "a.npy")
    assert out.dtype == np.float32 and out.shape == (6, 17, 23)
    np.testing.assert_array_equal(out, data.astype(np.float32))


@pytest.mark.parametrize("dtype", [bool, np.complex64])
def test_npy_of_no_real_number_type_is_refused(tmp_path, seq, dtype):
    """A mask or a complex array is not an image sequence (it was once tracked silently as 0/1 frames)."""
    np.save(tmp_path / "a.npy", seq.astype(dtype))
    with pytest.raises(InputError, match=rf"a\.npy: dtype {np.dtype(dtype)} is not a real number type"):
        io.read_frames(tmp_path / "a.npy")


def test_npz_frames(tmp_path, seq):
    np.savez(tmp_path / "a.npz", frames=seq, other=np.zeros(3))
    np.testing.assert_array_equal(io.read_frames(tmp_path / "a.npz"), seq.astype(np.float32))
    np.savez(tmp_path / "b.npz", images=seq)
    with pytest.raises(InputError, match=r"b\.npz.*no array 'frames'.*images"):
        io.read_frames(tmp_path / "b.npz")


def test_streaming_npy_is_lazy(tmp_path, seq):
    np.save(tmp_path / "a.npy", seq)
    stream = io.iter_frames(tmp_path / "a.npy")
    assert isinstance(stream, types.GeneratorType)
    first = next(stream)
    assert first.shape == (17, 23) and first.dtype == np.float32
    assert len(list(stream)) == 5
    src = io.open_frames(tmp_path / "a.npy")
    assert src.shape == (17, 23) and src.n_frames == 6


def test_video_colour_to_grey(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (32, 24))
    colours = [(10, 100, 200), (200, 50, 0), (0, 0, 0), (255, 255, 255)]
    for bgr in colours:
        writer.write(np.full((24, 32, 3), bgr, np.uint8))
    writer.release()
    frames = io.read_frames(path)
    assert frames.shape == (4, 24, 32)
    expected = [cv2.cvtColor(np.full((1, 1, 3), c, np.uint8), cv2.COLOR_BGR2GRAY)[0, 0] for c in colours]
    np.testing.assert_allclose(frames.mean(axis=(1, 2)), expected, atol=3)  # MJPG is lossy
    assert sum(1 for _ in io.iter_frames(path)) == 4


@pytest.mark.parametrize("suffix,dtype", [(".png", np.uint8), (".png", np.uint16), (".tif", np.uint16), (".bmp", np.uint8)])
def test_image_folder_sorted_by_name(tmp_path, rng, suffix, dtype):
    top = 255 if dtype == np.uint8 else 16383
    imgs = [rng.integers(0, top, size=(9, 11)).astype(dtype) for _ in range(12)]
    for k, img in enumerate(imgs):
        assert cv2.imwrite(str(tmp_path / f"frame_{k}{suffix}"), img)
    (tmp_path / "notes.txt").write_text("ignored")
    out = io.read_frames(tmp_path)
    np.testing.assert_array_equal(out, np.stack(imgs).astype(np.float32))  # frame_2 before frame_10


def test_colour_images_become_grey(tmp_path, rng):
    img = rng.integers(0, 255, size=(5, 7, 3)).astype(np.uint8)
    for k in range(2):
        cv2.imwrite(str(tmp_path / f"{k}.png"), img)
    np.testing.assert_array_equal(io.read_frames(tmp_path)[0], cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))


def test_array_input(seq):
    assert io.read_frames(seq).shape == seq.shape


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.npy: no such file"):
        io.read_frames(tmp_path / "nope.npy")


def test_unknown_type(tmp_path):
    (tmp_path / "a.xyz").write_text("x")
    with pytest.raises(InputError, match=r"a\.xyz: unknown file type '\.xyz'"):
        io.read_frames(tmp_path / "a.xyz")


@pytest.mark.parametrize("name", ["a.npy", "a.npz", "a.mp4"])
def test_empty_file(tmp_path, name):
    (tmp_path / name).write_bytes(b"")
    with pytest.raises(InputError, match=f"{name}: file is empty"):
        io.read_frames(tmp_path / name)


def test_corrupt_files(tmp_path):
    (tmp_path / "a.npy").write_bytes(b"not an array at all")
    with pytest.raises(InputError, match=r"a\.npy: not a readable \.npy file"):
        io.read_frames(tmp_path / "a.npy")
    (tmp_path / "b.mp4").write_bytes(b"\x00garbage" * 100)
    with pytest.raises(InputError, match=r"b\.mp4: unreadable video"):
        io.read_frames(tmp_path / "b.mp4")


@pytest.mark.parametrize("shape", [(17, 23), (2, 3, 4, 5)])
def test_wrong_number_of_dimensions(tmp_path, shape):
    np.save(tmp_path / "a.npy", np.zeros(shape))
    with pytest.raises(InputError, match=rf"a\.npy: array has {len(shape)} dimensions.*expected 3"):
        io.read_frames(tmp_path / "a.npy")


def test_non_real_dtype(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros((3, 4, 5), complex))
    with pytest.raises(InputError, match="not a real number type"):
        io.read_frames(tmp_path / "a.npy")


@pytest.mark.parametrize("bad,word", [(np.nan, "NaN"), (np.inf, "inf"), (-np.inf, "inf")])
def test_nan_and_inf(tmp_path, bad, word):
    data = np.zeros((4, 5, 6), np.float32)
    data[2, 3, 1] = bad
    np.save(tmp_path / "a.npy", data)
    with pytest.raises(InputError, match=rf"a\.npy: frame 2 contains {word}"):
        io.read_frames(tmp_path / "a.npy")


def test_mixed_sizes(tmp_path):
    cv2.imwrite(str(tmp_path / "0.png"), np.zeros((8, 8), np.uint8))
    cv2.imwrite(str(tmp_path / "1.png"), np.zeros((8, 9), np.uint8))
    with pytest.raises(InputError, match=r"1\.png: image 1 has size 8x9.*mixed sizes"):
        io.read_frames(tmp_path)


def test_empty_folder(tmp_path):
    with pytest.raises(InputError, match="holds no"):
        io.read_frames(tmp_path)


def test_too_few_frames(tmp_path, seq):
    np.save(tmp_path / "a.npy", seq)
    with pytest.raises(InputError, match=r"a\.npy: 6 frame\(s\), but at least 7 are needed"):
        io.read_frames(tmp_path / "a.npy", min_frames=7)
    with pytest.raises(InputError, match="at least 7"):
        next(io.iter_frames(tmp_path / "a.npy", min_frames=7))


def test_prefetched_frames_are_the_same_frames_in_order(tmp_path, seq):
    np.save(tmp_path / "a.npy", seq)
    direct = list(io.iter_frames(tmp_path / "a.npy"))
    ahead = list(io.prefetched(io.iter_frames(tmp_path / "a.npy"), depth=2))  # the decoder waits on a full queue
    assert len(ahead) == len(direct) == 6
    for a, b in zip(ahead, direct):
        np.testing.assert_array_equal(a, b)


def test_a_decoding_error_reaches_the_caller_at_its_frame():
    def frames():
        yield np.zeros((3, 3), np.float32)
        yield np.ones((3, 3), np.float32)
        raise InputError("clip.mp4: declares 9 frames, only 2 decoded")

    got = []
    with pytest.raises(InputError, match="only 2 decoded"):
        for frame in io.prefetched(frames()):
            got.append(float(frame[0, 0]))
    assert got == [0.0, 1.0]


def test_a_caller_that_stops_early_stops_the_decoder():
    import threading

    closed, produced = threading.Event(), []

    def frames():
        try:
            for k in range(1000):
                produced.append(k)
                yield np.full((2, 2), k, np.float32)
        finally:
            closed.set()

    stream = io.prefetched(frames(), depth=4)
    assert float(next(stream)[0, 0]) == 0.0
    stream.close()  # the caller leaves the loop (an error in the tracker, a break)
    assert closed.is_set() and len(produced) <= 1 + 4 + 2  # the frame in hand, a full queue, one being put
    assert not any(t.name == "frame-decoder" for t in threading.enumerate())
