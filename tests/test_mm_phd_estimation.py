"""MM-PHD's class extraction (tbd_taichi.methods.mm_phd.estimation) against plain references."""

import numpy as np
import pytest

from tbd_taichi.methods.mm_phd.estimation import k_means_labels, merged_labels


def merged_labels_reference(pos, labels, distance):
    """Join the nearest pair of classes (centres recomputed from the members each time) while closer than
    ``distance``: the definition, O(k³)."""
    labels = labels.copy()
    while True:
        ids = np.unique(labels)
        if len(ids) < 2:
            return labels
        centres = np.array([pos[labels == i].mean(axis=0) for i in ids])
        gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.eye(len(ids)) * 1e9
        a, b = np.unravel_index(np.argmin(gaps), gaps.shape)
        if gaps[a, b] >= distance:
            return labels
        labels[labels == ids[b]] = ids[a]


@pytest.mark.parametrize("seed", range(40))
def test_merged_labels_match_the_definition(seed):
    rng = np.random.default_rng(seed)
    n, k = int(rng.integers(1, 300)), int(rng.integers(1, 50))
    pos = rng.uniform(0, rng.uniform(5, 100), (n, 2))
    labels = rng.integers(0, k, n) * 3 + 1  # ids with gaps, not 0..k−1
    distance = rng.uniform(0, 20)
    assert np.array_equal(merged_labels(pos, labels, distance), merged_labels_reference(pos, labels, distance))


def test_merged_labels_join_a_chain_through_the_moving_centre():
    """Classes at x = 0, 4 and 10: at merge distance 5 the first two join (centre 2), and the third, 8 px from
    that centre, stays apart; at 8.1 it joins too."""
    pos = np.array([[0.0, 0], [4, 0], [10, 0]])
    out = merged_labels(pos, np.array([0, 1, 2]), 5.0)
    assert list(out) == [0, 0, 2]
    assert list(merged_labels(pos, np.array([0, 1, 2]), 8.1)) == [0, 0, 0]


@pytest.mark.filterwarnings("error")
def test_k_means_asks_no_more_classes_than_distinct_points():
    """round(n̂) can exceed the distinct positions drawn (a real clip's detector: hundreds of classes on a few
    bright cells): k-means++ then divided 0/0 and warned; now the points' three places give three classes."""
    pos = np.repeat(np.array([[1.0, 1.0], [5.0, 1.0], [1.0, 9.0]]), [20, 5, 1], axis=0)
    labels = k_means_labels(pos, 12, np.random.default_rng(0))
    assert len(np.unique(labels)) == 3
    assert all(len(np.unique(labels[np.all(pos == p, axis=1)])) == 1 for p in pos)
