"""Close multi-target scenarios (issue 43, item 4): two or three dim targets crossing or flying in parallel a few
pixels apart, and the scores that matter there: per-target DSR (Eq. 48), OSPA and identity swaps.

Geometry (x = column, y = row, pixel centres at integers, frame 0-based).  All targets move at the same
``speed`` (px/frame) on straight lines, with no process noise, so that the separation is what the scenario says:

* ``crossing``: target k's heading is ``heading + (k − (n − 1)/2)·angle/(n − 1)`` (degrees); at the middle frame
  the targets stand ``separation`` px apart along the mean heading, across their relative velocity, so their
  paths cross (an X for two targets) and that is their closest approach (exact for two targets; for three,
  ``Scenario.params["closest_px"]`` gives the figure);
* ``parallel``: the same heading for all, side by side ``separation`` px apart for the whole sequence.

Sensor as in :mod:`tbd_taichi.simulate`: the Gaussian PSF of Eq. 14 point-sampled at pixel centres, intensity
from the SNR (Eq. 1) and white N(0, σ²) noise.

Identity swaps follow CLEAR MOT (Bernardin & Stiefelhagen 2008): per frame, a target keeps the track it was
matched to while that track is within the gate; the others are matched by the optimal assignment
(``scipy.optimize.linear_sum_assignment``) on distance below the gate; a swap is counted when a target's
matched track differs from the one it was last matched to.
"""
from __future__ import annotations

import math

import numpy as np

from . import metrics
from .errors import ParameterError
from .simulate import Scenario, check_memory, in_view, intensity_for_snr, render_scene

GEOMETRIES = ("crossing", "parallel")


def formation_states(geometry: str, targets: int, separation: float, shape, frames: int, speed: float,
                     heading: float, angle: float) -> np.ndarray:
    """(targets, frames, 5) states [x, vx, y, vy, 0] of the formation (intensity filled in by the caller)."""
    h, w = shape
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    mean = math.radians(heading)
    along, across = np.array([math.cos(mean), math.sin(mean)]), np.array([-math.sin(mean), math.cos(mean)])
    t = np.arange(frames) - (frames - 1) / 2.0  # frames from the middle one
    states = np.zeros((targets, frames, 5))
    for k in range(targets):
        offset = k - (targets - 1) / 2.0
        theta = mean + (math.radians(angle) * offset / max(targets - 1, 1) if geometry == "crossing" else 0.0)
        v = speed * np.array([math.cos(theta), math.sin(theta)])
        pos = centre + offset * separation * (along if geometry == "crossing" else across) + t[:, None] * v
        states[k, :, 0], states[k, :, 2] = pos[:, 0], pos[:, 1]
        states[k, :, 1], states[k, :, 3] = v
    return states


def closest_approach(states: np.ndarray) -> float:
    """The smallest distance between any two targets in any frame, px (inf for one target)."""
    xy = states[:, :, [0, 2]]
    d = [np.hypot(*(xy[i] - xy[j]).T).min() for i in range(len(xy)) for j in range(i + 1, len(xy))]
    return float(min(d, default=math.inf))


def check_formation(geometry, targets, separation, shape, frames, snr, speed, angle) -> None:
    """A one-line ParameterError for the first argument out of range (before any frame is made)."""
    from .validate import positive, whole

    if geometry not in GEOMETRIES:
        raise ParameterError(f"geometry must be one of {', '.join(GEOMETRIES)}, got {geometry!r}")
    whole("targets", targets, 1)
    whole("frames", frames, 2)
    positive("separation", separation)
    positive("snr", snr)
    positive("speed", speed, 0.0, closed=True)
    if not 0 < angle < 180:
        raise ParameterError(f"angle must be in (0, 180) degrees, got {angle!r}")
    if len(shape) != 2 or min(shape) < 8:
        raise ParameterError(f"shape must be (H, W) with H, W ≥ 8, got {tuple(shape)}")
    check_memory(shape, frames)


def simulate_formation(geometry: str = "crossing", targets: int = 2, separation: float = 5.0, snr: float = 2.0,
                       seed: int = 0, *, shape=(100, 100), frames: int = 80, speed: float = 0.8,
                       heading: float = 20.0, angle: float = 60.0, psf_sigma: float = 0.7,
                       noise_sigma: float = 1.0) -> Scenario:
    """A :class:`~tbd_taichi.simulate.Scenario` of ``targets`` targets in ``geometry`` (module notes): frames
    (T, H, W) float32 and the truth of the frames each target's centre is in view.  ``seed`` draws the noise."""
    shape = tuple(int(s) for s in shape)
    check_formation(geometry, targets, separation, shape, frames, snr, speed, angle)
    states = formation_states(geometry, targets, float(separation), shape, frames, float(speed), float(heading),
                              float(angle))
    states[:, :, 4] = intensity_for_snr(snr, psf_sigma, noise_sigma)
    paths = [(path, in_view(path, shape, 0.0)) for path in states]
    images, truth = render_scene(paths, shape, frames, psf_sigma, noise_sigma, np.random.default_rng(seed))
    params = dict(geometry=geometry, targets=targets, separation=float(separation), snr=snr, seed=seed,
                  shape=list(shape), frames=frames, speed=speed, heading=heading, angle=angle,
                  psf_sigma=psf_sigma, noise_sigma=noise_sigma, closest_px=closest_approach(states))
    return Scenario(images, truth, params)


def matched_tracks(tracks: np.ndarray, truth: np.ndarray, gate: float = metrics.T0) -> dict[int, list]:
    """Per target id, its CLEAR-MOT match in each of its frames: [(frame, track_id or None), …] (module notes)."""
    from scipy.optimize import linear_sum_assignment

    out: dict[int, list] = {int(k): [] for k in np.unique(truth["target_id"])}
    last: dict[int, int] = {}
    for f in np.unique(truth["frame"]):
        tr, est = truth[truth["frame"] == f], tracks[tracks["frame"] == f]
        d = np.hypot(tr["x"][:, None] - est["x"][None, :], tr["y"][:, None] - est["y"][None, :])
        ids = est["track_id"].tolist()
        match: dict[int, int] = {}
        for i, target in enumerate(tr["target_id"].tolist()):  # keep last frame's match while it is in the gate
            j = ids.index(last[target]) if last.get(target) in ids else -1
            if j >= 0 and d[i, j] < gate and j not in match.values():
                match[i] = j
        free_t = [i for i in range(len(tr)) if i not in match]
        free_e = [j for j in range(len(est)) if j not in match.values()]
        if free_t and free_e:
            cost = d[np.ix_(free_t, free_e)]
            rows, cols = linear_sum_assignment(np.where(cost < gate, cost, 1e6))
            match.update({free_t[r]: free_e[c] for r, c in zip(rows, cols) if cost[r, c] < gate})
        for i, target in enumerate(tr["target_id"].tolist()):
            track = ids[match[i]] if i in match else None
            out[target].append((int(f), track))
            if track is not None:
                last[target] = track
    return out


def identity_swaps(tracks: np.ndarray, truth: np.ndarray, gate: float = metrics.T0) -> dict[int, int]:
    """Per target id, its identity swaps: each time its matched track changes to another track (CLEAR MOT's ID
    switch), and each time it is matched to a track that was last matched to another target (a track that hops
    from one target to the other, which CLEAR MOT's count alone misses when the first target is lost)."""
    swaps = {target: 0 for target in np.unique(truth["target_id"]).tolist()}
    last_track: dict[int, int] = {}  # target → its last matched track
    last_target: dict[int, int] = {}  # track → its last matched target
    matches = matched_tracks(tracks, truth, gate)
    events = sorted((f, target, track) for target, seq in matches.items() for f, track in seq if track is not None)
    for _, target, track in events:
        changed = last_track.get(target, track) != track
        hopped = last_target.get(track, target) != target
        swaps[target] += changed or hopped
        last_track[target], last_target[track] = track, target
    return swaps


def formation_scores(tracks, truth, n_frames: int, gate: float = metrics.T0) -> dict:
    """Per-target DSR (Eq. 48) and identity swaps, the smallest target DSR, mean OSPA and false tracks."""
    tracks = metrics.as_table(tracks, ("frame", "track_id", "x", "y"), "tracks")
    truth = metrics.as_table(truth, ("frame", "target_id", "x", "y"), "truth")
    per = metrics.target_scores(tracks, truth, gate)
    swaps = identity_swaps(tracks, truth, gate)
    return dict(dsr={k: s["dsr"] for k, s in per.items()}, min_dsr=min(s["dsr"] for s in per.values()),
                swaps=swaps, total_swaps=sum(swaps.values()), ospa=metrics.mean_ospa(tracks, truth, n_frames=n_frames),
                false_tracks=metrics.false_tracks(tracks, truth, gate))


__all__ = ["GEOMETRIES", "closest_approach", "formation_scores", "identity_swaps", "matched_tracks",
           "simulate_formation"]
