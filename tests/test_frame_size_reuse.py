"""Fields reused by a tracker at another frame size of their size class (``backend.reusable``) give the same tracks
as fields of its own, for MM-PHD, top-hat + PF, feature-fusion and the multiaspect filters (SGDS-PF's:
tests/test_sgds.py): nothing of the other frame's values, past the smaller frame or at the other width, reaches the
tracks."""
import gc

import numpy as np
import pytest

import tbd_taichi as tbd
from tbd_taichi import methods

SHAPES = ((33, 40), (61, 57))
SNR = {"mm-phd": 3.0, "tophat-pf": 8.0, "feature-fusion": 6.0, "ma-rs": 6.0}


def first_box(scene):
    """A 7 × 7 box (x, y, w, h) centred on the scene's first target at frame 0 (the feature-fusion tracker's)."""
    row = scene.truth[scene.truth["frame"] == 0][0]
    return (float(row["x"]) - 3.0, float(row["y"]) - 3.0, 7.0, 7.0)


@pytest.mark.parametrize("method", ["mm-phd", "tophat-pf", "feature-fusion", "ma-rs"])
def test_fields_reused_at_another_size_of_the_class_give_the_same_tracks(method):
    scenes = {shape: tbd.simulate(shape, 24, snr=SNR[method], seed=6) for shape in SHAPES}

    def run(shape):
        box = {"init_box": first_box(scenes[shape])} if method == "feature-fusion" else {}
        tracker = methods.make_tracker(method, shape, seed=3, **box)
        rows = [row for frame in scenes[shape].frames for row in tracker.update(frame)]
        return tracker, np.asarray(rows + list(tracker.finish()), dtype=object)

    def fields(tracker):
        return tracker.pool.k._target if method in ("mm-phd", "ma-rs") else tracker.k._target

    for shape, other in (SHAPES, SHAPES[::-1]):
        own, fresh = run(shape)  # kept alive: its fields are not lent
        first, _ = run(other)
        lent = fields(first)
        del first
        gc.collect()  # the other size's fields go back to the spare list
        reused, tracks = run(shape)
        assert fields(reused) is lent
        assert len(fresh) > 5
        assert tracks.tolist() == fresh.tolist()
        del own, reused
        gc.collect()
