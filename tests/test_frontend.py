"""The tracker's front end (normalisation + saliency), in this process and in a second one."""
import os
from multiprocessing import shared_memory

import numpy as np
import pytest

import tbd_taichi as tbd
from tbd_taichi import cli, tables
from tbd_taichi.background import Preprocessor
from tbd_taichi.errors import InputError, WorkerError
from tbd_taichi.frontend import FrontEnd, FrontEndProcess
from tbd_taichi.saliency import SaliencyExtractor
from tbd_taichi.methods.sgds import SGDSPF

SHAPE = (40, 52)
OPTIONS = dict(snr=1.4, L_ib=30, psf_sigma=0.7, background="none", bad_pixels=True, engine="taichi")


def reference_frames(frames):
    """z and proposal of every frame from the stages themselves (details=True copies each proposal)."""
    pre = Preprocessor(SHAPE, "none", True, "taichi")
    ext = SaliencyExtractor(SHAPE, snr=1.4, block_size=30, psf_sigma=0.7, details=True)
    zs = [pre(f, t) for t, f in enumerate(frames)]
    out = [s for z in zs for s in ext.push(z)] + ext.flush()
    return zs, {s.frame: s.proposal for s in out}


@pytest.mark.parametrize("front_end", [FrontEnd, FrontEndProcess])
def test_front_ends_give_every_frame_its_own_z_and_proposal(front_end):
    """Both front ends against the stages run directly, bit for bit, the last two frames (emitted
    together at the end) included; FrontEnd lags two frames, FrontEndProcess three."""
    frames = tbd.simulate(SHAPE, 9, 2.0, seed=3).frames
    zs, proposals = reference_frames(frames)
    front = front_end(SHAPE, **OPTIONS)
    lag = 3 if front_end is FrontEndProcess else 2
    got = []
    for t, frame in enumerate(frames):
        done = front.push(frame)
        assert [f.frame for f in done] == ([t - lag] if t >= lag else [])
        got += done
    got += front.finish()
    front.close()
    assert [f.frame for f in got] == list(range(9))
    for f in got:
        np.testing.assert_array_equal(f.z, zs[f.frame])
        np.testing.assert_array_equal(f.proposal, proposals[f.frame], err_msg=f"frame {f.frame}")
    assert not np.array_equal(proposals[7], proposals[8])  # the two last frames differ, so a mix-up shows


def test_tracks_are_the_same_with_the_front_end_process(tmp_path):
    scene = tbd.simulate((56, 64), 30, 3.0, seed=2)
    np.save(tmp_path / "seq.npy", scene.frames)
    outs = []
    for extra in ([], ["--frontend-process"]):
        out = tmp_path / f"t{len(extra)}.csv"
        assert cli.main(["track", str(tmp_path / "seq.npy"), "--snr", "3", "--out", str(out)] + extra) == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] and len(outs[0].splitlines()) > 5
    online = []
    for flag in (False, True):
        tracker = SGDSPF((56, 64), snr=3.0, frontend_process=flag)
        rows = [r for frame in scene.frames for r in tracker.update(frame)]
        tracker.finish()
        online.append((len(rows), tables.make_table(tracker.online_rows, tables.TRACK_DTYPE)))
    np.testing.assert_array_equal(online[0][1], online[1][1])  # the same online rows, one frame later
    assert online[1][0] < online[0][0]


def test_front_end_process_errors_name_the_problem():
    front = FrontEndProcess(SHAPE, **OPTIONS)
    names = [m.name for m in front._finalizer.peek()[2][2]]  # the finalizer's (channel, process, memory)
    front.push(np.zeros(SHAPE, np.float32))
    bad = np.zeros(SHAPE, np.float32)
    bad[3, 4] = np.nan
    with pytest.raises(InputError, match="frame 1 contains NaN or inf"):
        front.push(bad)
    with pytest.raises(InputError, match=r"frame 1 has shape \(40, 51\)"):
        front.push(np.zeros((40, 51)))
    front.push(np.ones(SHAPE, np.float32))  # a bad frame changes nothing: this is frame 1
    front._process.kill()
    with pytest.raises(WorkerError, match="front-end process ended unexpectedly"):
        for _ in range(3):
            front.push(np.zeros(SHAPE, np.float32))
    front.close()
    for name in names:  # the shared memory is freed
        with pytest.raises(FileNotFoundError):
            shared_memory.SharedMemory(name=name)
    with pytest.raises(WorkerError, match="front-end process: ParameterError: unknown background 'sky'"):
        FrontEndProcess(SHAPE, **{**OPTIONS, "background": "sky"})


def test_frontend_process_is_for_sgds_only(tmp_path, capsys):
    np.save(tmp_path / "seq.npy", np.zeros((6, 16, 16), np.float32))
    assert cli.main(["track", str(tmp_path / "seq.npy"), "--method", "pf", "--frontend-process", "--out",
                     str(tmp_path / "t.csv")]) == 2
    assert "--frontend-process applies to --method sgds only" in capsys.readouterr().err


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="Linux scheduling policies")
def test_front_end_process_runs_at_idle_priority_on_the_last_workers_cpu():
    """With pinned CPU workers the child runs on the last worker's CPU at SCHED_IDLE (every thread), so it
    never delays a worker; without them it is left to the scheduler."""
    from tbd_taichi import backend

    front = FrontEndProcess(SHAPE, **OPTIONS)
    try:
        front.push(np.zeros(SHAPE, np.float32))  # answered: the child has set itself up
        threads = [int(t) for t in os.listdir(f"/proc/{front._process.pid}/task")]
        policies = {os.sched_getscheduler(t) for t in threads}
        cpus = {frozenset(os.sched_getaffinity(t)) for t in threads}
        if backend.pinned_workers():
            last = max(os.sched_getaffinity(backend.pinned_workers()[-1]))
            assert policies == {os.SCHED_IDLE} and cpus == {frozenset({last})}
            assert last == backend.background_cpu()
        else:
            assert os.SCHED_IDLE not in policies and backend.background_cpu() is None
    finally:
        front.close()
