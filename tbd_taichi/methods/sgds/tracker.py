"""SGDS-PF: the saliency-guided double-stage particle filter (Jia et al., Sensors 2022, §2.2–2.3).

Per processed frame f (two frames behind the input, because of the saliency accumulation):

1. **Saliency** (Eqs. 20–33): the per-block proposal map OPsal_N of frame f.
2. **Searching mode** (Algorithm 1): one searching PF per image block, all in one particle
   pool.  Newborn and initial particles are drawn from the block's proposal map (Eqs. 34–35),
   labelled with their particle population (PP) by Eq. 36 (8-connected components of the
   proposal support, ``cv2.connectedComponents``); existence, propagation, weights,
   normalisation and resampling as in §2.1; the weakest PPs are eliminated (Eq. 37, P_e of
   the block's particles per frame); PP states follow Eq. 38; a PP with PTp > T_PTp and
   PE > T_PE is a potential target and moves, with its particles, to the tracking mode.
3. **Tracking mode** (Algorithm 2): one tracking PF of N_tpf particles per potential target, all
   in a second pool; newborns copy a random E = 1 particle of the same track.  Each frame the
   track's estimate (Eq. 19) extends its path (Eq. 39) and its confidence C is updated by
   ICEF (Eq. 40) and SCEF (Eqs. 41–42) (Eq. 43).  C < T_ft ends the track; N_rt > T_rt
   (frames with C = 1) confirms it.

Where the paper is open or departs, the choices (each a parameter where it can be, with the paper's value
available) are listed with their reasons and measured effects in docs/methods/sgds.md: Eq. 26's newborn
intensities, PE = ΣE/N_pp, SCEF's sound reading over the E = 1 particles (:func:`~.confirmation.scef`), the ICEF
window and the long-window confirmation (:func:`~.confirmation.windowed_icef`, :func:`~.confirmation.held_compact`),
the multi-frame LEF and the MSW from candidates (``PAPER_SALIENCY`` restores Eqs. 29 and 40 as printed), the
ends of a track (out of the image, 3 frames without an E = 1 particle), one track per target (saliency masked
and potential targets dropped within 2 px of a track, the younger of two close tracks removed), and the
hand-over timing (a PP handed over at frame f starts its track with its Eq. 38 estimate at f; its tracking PF
first steps at f + 1).
"""
from __future__ import annotations

import math
import time
from collections import deque

import cv2
import numpy as np

from ... import backend
from ...background import DEFAULT_BACKGROUND
from ...errors import InputError, ParameterError
from ...frontend import FrontEnd, FrontEndProcess, FrontFrame
from ...kernels.particles.layout import STATE
from ...kernels.loops import block_class
from ...kernels.populations import pixel_class
from ...particles import ParticlePool
from ...peak_guard import running_peak_z
from ...tables import TRACK_DTYPE, make_table
from ..still_tracks import StillTrackRule
from .backfill import backfilled_paths
from .confirmation import (DUPLICATE_RADIUS, ICEF_LOWER, TRACK_MASK_HALF, Track, msw_from_candidates, near_any,
                           near_any_of, scef, within_duplicate_radius)
from ..registry import OneSequence
from .params import SGDSParams
from .handover import HANDOVER_STREAM, RecentFrames, engine_kernels, multi_frame_draws
from .populations import resize_population
from .searching_pool import SearchingPool
from .track_states import TrackStates

MIN_FRAMES = 5
PIPELINE_STAGES = ("normalise", "saliency", "searching", "tracking")  # SGDSPF.stage_seconds


class SGDSPF(OneSequence):
    """Streaming SGDS-PF tracker.

    ``tracker = SGDSPF((H, W), snr=1.4, seed=0, engine="taichi", arch=None, **params)``;
    ``params`` override the Table 2 preset of :class:`~tbd_taichi.methods.sgds.params.SGDSParams`.
    ``update(frame)`` takes one raw frame and returns the confirmed tracks' rows for the frame
    it has just finished, which is two frames behind (saliency needs frame f + 2).
    ``finish()`` processes the last two frames and returns every confirmed track with its
    whole path, which may begin before the track was confirmed (its history in the tracking PF) and, with
    ``backfill_frames`` > 0, up to that many frames before its hand-over (backfill.py).

    ``history=False`` keeps no paths (only each track's last point) and no online rows, so memory
    stays constant on endless streams; then ``finish()`` returns only the rows of the two flushed
    frames, and the caller keeps what ``update`` returned.

    ``frontend_process=True`` runs normalisation and saliency in a second process, one frame
    ahead (:mod:`tbd_taichi.frontend`): the same tracks, with ``update`` three frames behind;
    ``finish()`` ends that process.
    """

    def __init__(self, shape, snr: float = 1.4, seed: int = 0, engine: str = "taichi", arch: str | None = None,
                 max_tracks: int | None = None, background: str = DEFAULT_BACKGROUND, bad_pixels: bool = True,
                 history: bool = True, frontend_process: bool = False, **params):
        if len(shape) != 2 or min(shape) < 8:
            raise ParameterError(f"shape must be (H, W) with H, W ≥ 8, got {tuple(shape)}")
        if max_tracks is not None:
            params["max_tracks"] = max_tracks
        self.p = SGDSParams.for_snr(snr, **params)
        max_tracks = self.p.max_tracks
        self.shape = (int(shape[0]), int(shape[1]))
        self.seed, self.history = int(seed), bool(history)
        if engine == "taichi":
            backend.ensure_init(arch)
        p = self.p
        front = FrontEndProcess if frontend_process else FrontEnd
        self.front = front(self.shape, snr=p.snr, L_ib=p.L_ib, psf_sigma=p.psf_sigma, background=background,
                           bad_pixels=bad_pixels, engine=engine, lef_memory=p.lef_memory, lef_scale=p.lef_scale)
        self.grid = self.front.grid
        common = dict(engine=engine, q1=p.q1, q2=p.q2, psf_sigma=p.psf_sigma, noise_sigma=p.noise_sigma)
        # one searching PF per block, in a pool of the blocks' class: the spare groups stay empty (no map, no top-up)
        self.search = SearchingPool([p.N_sump] * block_class(self.grid.n_blocks), self.shape, seed=seed,
                                    map_capacity=pixel_class(self.shape), **common)
        self.tracks_pool = ParticlePool([p.N_tpf] * max_tracks, self.shape, seed=seed + 7919, **common)
        intensity = (max(p.snr - 2.0, 0.1), p.snr + 3.0)  # Eq. 26 as printed (σ units); see the module notes
        self.search.configure_groups(np.arange(self.grid.n_blocks), "map", pb=p.P_b, pd=p.P_d_search,
                                     vmax=p.V_limit, intensity=intensity, mu=p.mu)
        self.tracks_pool.configure_groups(np.arange(max_tracks), "copy", pb=p.P_b, pd=p.P_d_track,
                                          vmax=p.V_limit, intensity=intensity)
        pixels = self.shape[0] * self.shape[1]  # ICEF's thresholds scale with the frame area
        self.icef_ratio = p.icef_ratio_for(pixels)  # the ICEF window's threshold
        self.icef_lower = p.icef_ratio_for(pixels, ICEF_LOWER)  # Eq. 40's 0.1, scaled
        self.confirm_log_ratio = math.log(p.icef_ratio_for(pixels, p.confirm_mean_ratio))  # the long window's
        self.pp_index = np.zeros(self.shape, np.int32)  # P_pp of Eq. 36 (0: no PP)
        self.next_pp = 1
        self.free_groups = list(range(max_tracks))[::-1]
        self.ended_groups: list[int] = []  # groups of tracks ended this frame: free at once, emptied by _start_tracks
        self.active: list[Track] = []  # in track-id order
        self.states = TrackStates(max_tracks, p.icef_window, p.confirm_window)  # their per-frame numbers, by group
        self.finished: list[Track] = []
        self.still_rule = StillTrackRule(self.p.still_frames, self.p.still_radius)  # which tracks the whole paths take
        self.recent = RecentFrames(self.p.handover_frames, self.shape)  # the frames the multi-frame hand-over sums over
        self.handover_kernels = engine_kernels(engine) if self.p.handover_frames else None
        self.next_track_id = 1
        self.online_rows: list[tuple] = []
        self.stage_seconds = dict.fromkeys(PIPELINE_STAGES, 0.0)  # cumulative wall time per stage
        if frontend_process:  # this process's wait for the front end (its own stages run alongside)
            self.stage_seconds["waiting"] = 0.0

    def _clock(self, stage: str, t0: float) -> float:
        now = time.perf_counter()
        self.stage_seconds[stage] += now - t0
        return now

    # ------------------------------------------------------------ input

    def update(self, frame) -> list[tuple]:
        """Add one raw frame; returns the confirmed rows (frame, track_id, x, y, vx, vy, I, C) of the
        frame finished now (frame t − 2, or t − 3 with ``frontend_process``), or [] before that."""
        self._check_open("update")
        t0 = time.perf_counter()
        done = self.front.push(frame)
        self._front_clock(t0)
        return [row for f in done for row in self._process(f)]

    def finish(self) -> np.ndarray:
        """Process the last frames and return the tracks table of every confirmed track's whole path."""
        if self.frames_in < MIN_FRAMES:
            raise InputError(f"{self.frames_in} frame(s), but SGDS-PF needs at least {MIN_FRAMES}")
        self._close_sequence()
        t0 = time.perf_counter()
        done = self.front.finish()
        self._front_clock(t0)
        rows = [row for f in done for row in self._process(f)]
        self.front.close()
        return self.whole_paths() if self.history else make_table(rows, TRACK_DTYPE)

    @property
    def frames_in(self) -> int:
        """Raw frames taken so far (counted by the front end)."""
        return self.front.frames_in

    def close(self) -> None:
        """Release the front end (ends the front-end process, if any); ``finish`` does this too."""
        self.front.close()

    @property
    def timings(self) -> dict:
        """Cumulative wall seconds per pipeline stage (PIPELINE_STAGES, and 'waiting' with the front-end process)."""
        return dict(self.stage_seconds)

    def _front_clock(self, t0: float) -> None:
        """The front end's stage times (its own clock), and this process's wait for it."""
        self.stage_seconds.update(self.front.stage_seconds)
        if "waiting" in self.stage_seconds:
            self._clock("waiting", t0)

    def whole_paths(self, backfill: bool = True) -> np.ndarray:
        """Each reported track's whole path: from its first frame (before its confirmation) on; with
        ``min_peak_z`` > 0, from the first to the last frame it was reported in (the gaps between filled), since
        the guard judges the stretches before and after as too faint to report, and with ``still_frames`` > 0
        not a still track that went before it had been reported in still_frames frames (methods/still_tracks.py;
        docs/methods/sgds.md#real-video).  With ``backfill`` (and ``backfill_frames`` > 0, history kept, no
        ``min_peak_z`` gate) each path begins up to backfill_frames frames earlier (backfill.py)."""
        def kept(t: Track):
            if self.p.min_peak_z <= 0:
                return list(t.path)
            first, last = t.reported_span
            return [row for row in t.path if first <= row[0] <= last]

        paths = {t.track_id: kept(t) for t in self.finished + self.active if t.whole}
        frames = self.p.backfill_frames if backfill and self.history and self.p.min_peak_z <= 0 else 0
        before = backfilled_paths(paths, frames, self.shape) if frames else {}
        rows = [(f, track, x, y, vx, vy, i, c) for track, path in paths.items()
                for (f, x, y, vx, vy, i, c) in before.get(track, []) + path]
        return make_table(rows, TRACK_DTYPE)

    def online(self) -> np.ndarray:
        """Rows as they were output online (from confirmation on)."""
        return make_table(self.online_rows, TRACK_DTYPE)

    # ------------------------------------------------------------ one frame

    def _process(self, front: FrontFrame) -> list[tuple]:
        """Frame f: both PF stages in one step (the tracking PFs of the tracks begun by frame f − 1), the
        tracks' confirmation, then Eq. 37's elimination and the hand-over of frame f's potential targets,
        whose tracking PFs first step at f + 1 (a handed PP's particles have already weighed frame f)."""
        f, z = front.frame, front.z
        self.recent.add(f, z)
        t0 = time.perf_counter()
        n_pp, est = self._filter_step(f, z, front)
        log_msw = self._log_msw(front)
        t0 = self._clock("searching", t0)
        rows = self._confirm_tracks(f, z, est, log_msw)
        t0 = self._clock("tracking", t0)
        self._eliminate_and_hand_over(f, n_pp)
        self._clock("searching", t0)
        if self.history:
            self.online_rows += rows
        return rows

    def _suppress_tracked(self, proposal: np.ndarray) -> None:
        """Zero the proposal in the ±TRACK_MASK_HALF px square around each active track (one target, one track),
        in place: ``proposal`` is the front frame's own copy, used for this frame's search only.  The squares' rows
        and columns are clipped to the image (an active track's nearest pixel lies inside it)."""
        if not self.active:
            return
        centres = np.floor(self._tracked_xy() + 0.5).astype(np.int64)
        side = np.arange(-TRACK_MASK_HALF, TRACK_MASK_HALF + 1)
        rows = np.clip(centres[:, 1, None] + side, 0, self.shape[0] - 1)
        columns = np.clip(centres[:, 0, None] + side, 0, self.shape[1] - 1)
        proposal[rows[:, :, None], columns[:, None, :]] = 0

    def _active_groups(self) -> np.ndarray:
        """The active tracks' groups, in track order."""
        return np.fromiter((t.group for t in self.active), np.int64, len(self.active))

    def _tracked_xy(self) -> np.ndarray:
        """(n, 2): the active tracks' last positions (x, y), in track order."""
        return self.states.xy[self._active_groups()]

    def _proposal_maps(self, proposal: np.ndarray, support: np.ndarray) -> dict:
        """Each block's proposal pixels (y·W + x, ascending) and their OPsal_N weights (f64), for the
        blocks that have any: {block: (pixels, weights)} (one stable sort by block, not a pass per block)."""
        pix = np.flatnonzero(support)
        blocks = self.grid.block_id.ravel()[pix]
        order = np.argsort(blocks, kind="stable")
        pix, blocks = pix[order], blocks[order]
        weights = proposal.ravel()[pix].astype(np.float64)
        bounds = np.searchsorted(blocks, np.arange(self.grid.n_blocks + 1))
        return {b: (pix[s:e], weights[s:e]) for b, (s, e) in enumerate(zip(bounds[:-1], bounds[1:])) if e > s}

    def _labels(self, support: np.ndarray) -> np.ndarray:
        """Eq. 36: existing PP ids where P_pp ≠ 0, else new ids from 8-connected components."""
        n, labels = cv2.connectedComponents(support.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        np.add(labels, np.int32(self.next_pp - 1), out=labels, where=support)  # component k → PP id next_pp − 1 + k
        self.next_pp += n - 1
        old = self.pp_index != 0
        old &= support
        np.copyto(labels, self.pp_index, where=old)
        return labels

    def _filter_step(self, f: int, z: np.ndarray, front: FrontFrame):
        """Algorithm 1's PF step on frame f (proposal maps, Eqs. 34–36, §2.1) and, in the same launch, Algorithm
        2's for the active tracks; the same launch numbers the searching PFs' particle populations with Eq. 37's
        quotas.  Returns their number and the tracking PFs' estimates (None without active tracks)."""
        p, pool = self.p, self.search
        proposal = front.proposal
        self._suppress_tracked(proposal)
        support = proposal > 0
        maps = self._proposal_maps(proposal, support)
        pool.set_proposal_map(maps, self._labels(support))
        has_map = np.zeros(pool.n_groups, bool)  # the spare groups of the blocks' class have none
        has_map[list(maps)] = True
        top_up = np.where(has_map, p.N_sump, pool.counts)
        quota = int(round(p.P_e * p.N_sump))  # Eq. 37: particles eliminated per block
        if not self.active and not pool.pairs_with(self.tracks_pool):
            return pool.step(f, z, top_up=top_up, quota=quota), None
        # with no active track the tracking pool's empty groups cost next to nothing, and one kernel (step_pair)
        # then serves every frame instead of three (the searching step, the tracking step, estimates)
        n_pp, est = pool.step_with(self.tracks_pool, f, z, top_up=top_up, quota=quota)
        return n_pp, est if self.active else None

    def _log_msw(self, front: FrontFrame) -> float:
        """ln MSW for Eq. 40 (``msw_reference``), after the searching PFs' step."""
        if self.p.msw_reference == "search":
            return float(self.search.max_log_weights().max())
        return msw_from_candidates(front.best_lef, self.shape[1], self._tracked_xy())

    def _eliminate_and_hand_over(self, f: int, n_pp: int) -> None:
        """Eq. 37 elimination, Eq. 38 PP states, potential targets, and the index image P_pp, over the ``n_pp``
        PPs that the step numbered.

        A PP is a (block, Seq) pair.  The step numbered the PPs of all blocks at once and set Eq. 37's quotas
        on the device; the host draws each PP's phase, and the pool eliminates, applies Algorithm 1's
        potential-target rule (PTp > T_PTp, PE > T_PE with PE = ΣE/N_pp, Eq. 38; a potential target near an
        active track is dropped, the others are handed over while tracking PFs are free) and hands over in one
        launch (``SearchingPool.eliminate_and_hand_over_numbered``), so only the handed-over particles' states
        come to the host, PP after PP, each in state order."""
        p, pool = self.p, self.search
        rng = np.random.default_rng([self.seed, f])
        tracked = self._tracked_xy().tolist()
        members, sizes = pool.eliminate_and_hand_over_numbered(rng.random(n_pp), self.pp_index, p.T_PTp, p.T_PE,
                                                               tracked, DUPLICATE_RADIUS, len(self.free_groups))
        self._start_tracks(f, members, sizes, rng, tracked)

    def _start_tracks(self, f: int, members: dict | None, sizes: list, rng: np.random.Generator,
                      tracked: list) -> None:
        """A tracking PF for each handed-over PP: ``members`` holds their particles' states, PP after
        PP (``sizes`` each), resized to N_tpf particles (Algorithm 2), all loaded in one launch, which also
        empties the groups of the tracks ended this frame (``ended_groups``; one launch fewer than emptying them
        apart).  ``tracked``: the active tracks' last positions, to which the new tracks are added."""
        n_tpf = self.p.N_tpf
        starts = np.cumsum(sizes) - sizes
        mean = self._pp_means(members, starts) if len(sizes) else {}
        near_tracked = near_any_of(tracked, mean["x"], mean["y"]).tolist() if len(sizes) else []
        chosen, groups = [], []  # (first particle, PP size, uniforms) of each PP handed over
        for k in range(len(sizes)):
            if not self.free_groups:
                break
            x, y = float(mean["x"][k]), float(mean["y"][k])
            if near_tracked[k] or near_any(tracked[len(tracked) - len(groups):], x, y):  # or a new track
                continue
            chosen.append((starts[k], sizes[k], rng.random(max(n_tpf, sizes[k]))))
            groups.append(self.free_groups.pop())
            track = Track(self.next_track_id, groups[-1], path=deque(maxlen=None if self.history else 1))
            self.next_track_id += 1
            track.path.append((f, x, y, float(mean["vx"][k]), float(mean["vy"][k]), float(mean["inten"][k]), 1.0))
            self.states.start(track.group, f, x, y)
            self.active.append(track)
            tracked.append((x, y))
        emptied, self.ended_groups = self.ended_groups, []
        if not groups and not emptied:
            return
        order = np.argsort(groups)
        picks = self._handed_over(f, members, chosen)
        index = np.concatenate([picks[k] for k in order]) if groups else np.zeros(0, np.int64)
        # the emptied groups that no new track took are touched with no particles: their count becomes 0
        self.tracks_pool.load_states(np.repeat(np.asarray(groups, np.int64)[order], n_tpf),
                                     {name: members[name][index] for name in STATE}, sorted(set(groups + emptied)))

    def _handed_over(self, f: int, members: dict, chosen: list) -> list:
        """For each PP handed over at frame f, (first particle, size, uniforms) in ``chosen``, the indices of the N_tpf
        particles its tracking PF takes: Algorithm 2's uniform elimination or copying (from the uniforms), or with
        ``handover_frames`` > 0 the multi-frame draw (handover.py; one launch for all of them, the k-th PP's
        generator keyed on draw k + 1)."""
        p = self.p
        if p.handover_frames == 0:
            return [start + resize_population(n, p.N_tpf, u) for start, n, u in chosen]
        rngs = [np.random.default_rng([self.seed, f, HANDOVER_STREAM, k + 1]) for k in range(len(chosen))]
        return multi_frame_draws(self.handover_kernels, members, [(start, n) for start, n, _ in chosen], p.N_tpf,
                                 self.recent, f, (p.psf_sigma, p.noise_sigma), rngs, p.handover_jitter)

    @staticmethod
    def _pp_means(members: dict, starts: np.ndarray) -> dict:
        """Eq. 38's PP state: per PP (particles from ``starts[k]`` on, each PP with an E = 1 particle)
        the mean x, y, vx, vy and intensity of its E = 1 particles (f64 sums)."""
        e = members["e"] == 1
        n_e = np.add.reduceat(e.astype(np.int64), starts)
        return {name: np.add.reduceat(np.where(e, members[name], 0).astype(np.float64), starts) / n_e
                for name in ("x", "y", "vx", "vy", "inten")}

    def _confirm_tracks(self, f: int, z: np.ndarray, est, log_msw: float) -> list[tuple]:
        """Algorithm 2 after the tracking PFs' step on frame f (estimates ``est``): paths (Eq. 39), confidences
        (Eqs. 40–43), confirmation and ends, for all groups at once (``TrackStates.step``); then the ended
        tracks end and the confirmed ones are reported, in track order; returns the rows of the tracks reported at f."""
        p, states = self.p, self.states
        if not self.active:
            return []
        finite = np.isfinite(est.x)
        scefs = scef(est.cov_e, p.T_devr)  # Eq. 41 over E = 1 particles (module notes)
        ended = states.step(f, finite, np.stack([est.x, est.y], axis=1), est.max_logw, log_msw, scefs,
                            (self.shape, p.T_ft, p.T_rt, self.icef_lower, self.icef_ratio, self.confirm_log_ratio))
        g = self._active_groups()
        moved = g[finite[g]]
        rows = np.stack([est.x[moved], est.y[moved], est.vx[moved], est.vy[moved], est.intensity[moved],
                         states.confidence[moved]], axis=1).tolist()
        tracks = list(self.active)  # _end_track removes from self.active
        for t, row in zip((t for t in tracks if finite[t.group]), rows):  # Eq. 39: the moved tracks' paths
            t.path.append((f, *row))
        if p.min_peak_z > 0:
            self._update_peak_z(g, z)
        out = []
        for i in np.flatnonzero(ended[g] | states.confirmed[g]).tolist():  # the events, in track order
            t = tracks[i]
            if ended[t.group]:
                self._end_track(t)
                continue
            t.confirmed = True
            if self._reportable(t) and states.last_frame[t.group] == f:
                out.append((f, t.track_id) + tuple(t.path[-1][1:]))
        self._merge_duplicates()
        return out

    def _update_peak_z(self, groups: np.ndarray, z: np.ndarray) -> None:
        """The running peak z (``running_peak_z``) of the tracks in ``groups`` at their last positions, after
        frame ``z``."""
        s = self.states
        s.peak_z[groups] = running_peak_z(s.peak_z[groups], z, s.xy[groups, 0], s.xy[groups, 1])

    def _reportable(self, t: Track) -> bool:
        """The confirmed track ``t`` is reported at this frame: always without the guard; with min_peak_z > 0 while
        its running peak z (``TrackStates.peak_z``) is at least min_peak_z: a real-video guard against confirmed
        clutter, which is fainter in z than the targets (docs/results/drone_ir.md).  The running mean starts at 0,
        so a track must stay bright for about ten frames; short-lived transients are not reported.  A track
        reported in ``keep_after`` frames needs only ``keep_peak_z`` (with keep_peak_z > 0): hysteresis, so that a
        proven target is not cut where it fades for a while."""
        if self.p.min_peak_z <= 0:
            t.reported = t.whole = True
            return True
        proven = t.reported and t.reported_frames >= self.p.keep_after and self.p.keep_peak_z > 0
        keep = self.p.keep_peak_z if proven else self.p.min_peak_z
        ok = self.states.peak_z[t.group] >= keep
        t.reported = t.reported or ok
        if ok:
            t.reported_frames += 1
            frame = t.path[-1][0]
            t.reported_span = (t.reported_span or (frame,))[:1] + (frame,)
            self.still_rule.reported(t, t.last_xy())
        return bool(ok)

    def _merge_duplicates(self) -> None:
        """Of two active tracks closer than DUPLICATE_RADIUS, the younger (larger id) ends; oldest first,
        and a track that has ended ends no other."""
        if len(self.active) < 2:
            return
        tracks = list(self.active)  # in track-id order; _end_track removes from self.active
        x, y = self._tracked_xy().T
        close = np.triu(within_duplicate_radius(x, y, x, y), 1)  # pairs (older, younger)
        if not close.any():
            return
        alive = np.ones(len(tracks), bool)
        for i in np.flatnonzero(close.any(axis=1)):
            if alive[i]:
                for j in np.flatnonzero(close[i] & alive):
                    alive[j] = False
                    self._end_track(tracks[j])

    def _end_track(self, t: Track) -> None:
        self.active.remove(t)
        self.free_groups.append(t.group)
        self.ended_groups.append(t.group)
        self.still_rule.ended(t, t.last_xy())
        if t.reported and self.history:
            self.finished.append(t)
