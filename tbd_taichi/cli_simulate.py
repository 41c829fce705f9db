"""``tbd-taichi simulate``: its options, the checks made before any work (:func:`check_simulate`) and the run, for
every scenario (jia2022, long2012, bruno2008, huo2022, guler2016)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import tables, validate
from .errors import TBDError

number, whole, positive = validate.cli_number, validate.whole, validate.positive


def _truth_csv_path(out: Path) -> Path:
    return out.with_name(out.stem + "_truth.csv")


def check_simulate(args) -> None:
    """The scenario's arguments (jia2022: --shape with sides ≥ 8, --frames, --snr, --motion stay|transit; long2012:
    --case, --snr-db; bruno2008: --ptcr, --exit-reentry, --frames; huo2022: --sequence, --frames; guler2016:
    --wall, --motion 1|2, --delta, --frames 4-5000, --wall-seed), the memory the frames need, and the two output
    files."""
    from .simulate import check_memory

    own = {"jia2022": ("--shape", "--frames", "--snr", "--motion", "--targets"), "long2012": ("--case", "--snr-db"),
           "bruno2008": ("--ptcr", "--exit-reentry", "--frames"), "huo2022": ("--sequence", "--frames"),
           "guler2016": ("--wall", "--motion", "--delta", "--frames", "--wall-seed")}
    given = {"--shape": args.shape, "--frames": args.frames, "--snr": args.snr, "--case": args.case,
             "--snr-db": args.snr_db, "--ptcr": args.ptcr, "--exit-reentry": args.exit_reentry or None,
             "--sequence": args.sequence, "--motion": args.motion, "--wall": args.wall, "--delta": args.delta,
             "--wall-seed": args.wall_seed, "--targets": args.targets}
    for flag, value in given.items():
        if value is not None and flag not in own[args.scenario]:
            owners = " or ".join(s for s, flags in own.items() if flag in flags)
            raise TBDError(f"{flag} applies to --scenario {owners}; --scenario {args.scenario} takes "
                           f"{', '.join(own[args.scenario])}")
    if args.scenario == "long2012":
        from .long2012 import check_case

        check_case(args.case or "5.2", args.snr_db)
    elif args.scenario == "bruno2008":
        from .bruno2008 import FRAMES, MIN_REENTRY_FRAMES, PTCRS, SHAPE, check_bruno2008

        check_bruno2008(PTCRS[0] if args.ptcr is None else args.ptcr, args.frames, args.exit_reentry)
        check_memory(SHAPE, MIN_REENTRY_FRAMES if args.exit_reentry else args.frames or FRAMES)
    elif args.scenario == "huo2022":
        from . import huo2022

        huo2022.check_huo2022(args.sequence or "fast", args.frames)
        check_memory(huo2022.SHAPE, args.frames or huo2022.FRAMES)
    elif args.scenario == "guler2016":
        from . import guler2016

        if args.motion not in (None, "1", "2"):
            raise TBDError(f"--motion {args.motion} is jia2022's; --scenario guler2016 takes --motion 1 or 2 "
                           "(the thesis's Motion 1, 2)")
        guler2016.check_guler2016(args.wall or "S1", int(args.motion or 1),
                                  guler2016.DELTA if args.delta is None else args.delta, args.frames)
        check_memory(guler2016.SHAPE, args.frames or guler2016.FRAMES)
    else:
        if args.motion not in (None, "stay", "transit"):
            raise TBDError(f"--motion {args.motion} is guler2016's; --scenario jia2022 takes --motion stay or transit")
        missing = [f for f, v in (("--shape", args.shape), ("--frames", args.frames), ("--snr", args.snr)) if v is None]
        if missing:
            raise TBDError(f"--scenario jia2022 needs {', '.join(missing)}")
        check_memory(validate.frame_shape("--shape", args.shape), args.frames)
    out = validate.output_path("--out", args.out, (".npz",))
    validate.output_path("--out (its truth CSV)", _truth_csv_path(out))


def cmd_simulate(args) -> int:
    from .simulate import simulate

    arrays = {}
    if args.scenario == "long2012":
        from .long2012 import simulate_long2012

        case = args.case or "5.2"
        scene = simulate_long2012(case, seed=args.seed, snr_db=args.snr_db)
        what = f"Long et al. 2012 §{case}"
    elif args.scenario == "bruno2008":
        from .bruno2008 import PTCRS, local_mean, simulate_bruno2008, streams

        ptcr = PTCRS[0] if args.ptcr is None else args.ptcr
        scene = simulate_bruno2008(seed=args.seed, ptcr_db=ptcr, exit_reentry=args.exit_reentry, frames=args.frames)
        arrays["local_mean"] = local_mean(streams(args.seed)[0]).astype(np.float32)  # the oracle mean (§4)
        what = f"Bruno et al. 2008, PTCR {ptcr:g} dB" + (
            f", exit at frame {scene.params['exit_frame']}, re-entry at {scene.params['entry_frame']}"
            if args.exit_reentry else "")
    elif args.scenario == "huo2022":
        from .huo2022 import simulate_huo2022

        scene = simulate_huo2022(args.sequence or "fast", seed=args.seed, frames=args.frames)
        what = f"Huo et al. 2022's {args.sequence or 'fast'} sequence, box truth"
    elif args.scenario == "guler2016":
        from .guler2016 import DELTA, simulate_guler2016

        scene = simulate_guler2016(args.wall or "S1", int(args.motion or 1),
                                   DELTA if args.delta is None else args.delta, seed=args.seed, frames=args.frames,
                                   wall_seed=args.wall_seed)
        p = scene.params
        what = (f"Güler 2016 wall {p['wall']} (wall seed {p['wall_seed']}), Motion {p['motion']}, "
                f"Δ {p['delta']:g} over the frame mean, uint16; "
                f"σ {p['sigma']:.2f}, SNR Δ/σ {p['snr']:.2f}, the thesis's Δ/(100σ) {p['snr_thesis']:.4f}")
    else:
        scene = simulate((args.shape[0], args.shape[1]), frames=args.frames, snr=args.snr, targets=args.targets or 1,
                         seed=args.seed, motion=args.motion or "stay")
        what = f"SNR {args.snr}"
    out = Path(args.out)
    np.savez_compressed(out, frames=scene.frames, truth=scene.truth, params=json.dumps(scene.params), **arrays)
    truth_csv = _truth_csv_path(out)
    tables.write_csv(scene.truth, truth_csv)
    t, h, w = scene.frames.shape
    print(f"wrote {out} ({t} frames of {h}x{w}, {len(np.unique(scene.truth['target_id']))} target(s), {what}) "
          f"and {truth_csv}")
    return 0


def add_simulate_parser(sub, common) -> None:
    """The ``simulate`` sub-command and its options."""
    sim = sub.add_parser("simulate", help="simulate a sequence (SGDS-PF section 3.1, Long et al. 2012 section 5, "
                         "Bruno et al. 2008 section 4, Huo et al. 2022 Table 1 or Güler 2016 section 3.1)",
                         description="Simulate dim targets in white Gaussian noise: SGDS-PF Eqs. 1, 14, 44-46 (--scenario jia2022) or Long et al. 2012 §5 with Eq. 4 and jitter (--scenario long2012 --case); "
                                     "or a multiaspect extended target in GMRF clutter on a smooth local mean, Bruno et al. 2008 Eqs. 1-9 and §4 (--scenario bruno2008 [--ptcr] [--exit-reentry]); "
                                     "or a one-pixel target set to the frame mean + Δ on a synthetic 14-bit wall recording, Güler 2016 §3.1 (--scenario guler2016 [--wall] [--motion 1|2] [--delta] [--wall-seed]; uint16 frames). "
                                     "Writes OUT (.npz with arrays 'frames' and 'truth'; bruno2008 adds 'local_mean') and OUT_truth.csv beside it "
                                     "(bruno2008 adds an integer 'aspect' column, 1-4).")
    sim.add_argument("--sequence", choices=("weak", "complex", "fast", "rotating"), default=None,
                     help="huo2022: a sequence after Huo et al.'s Table 1 (default fast)")
    sim.add_argument("--scenario", choices=("jia2022", "long2012", "bruno2008", "huo2022", "guler2016"),
                     default="jia2022",
                     help="jia2022: SGDS-PF's targets (default); long2012: Long et al. 2012's §5 scenes (--case); "
                          "bruno2008: Bruno et al. 2008's §4 scene, 120x120 (--ptcr, --exit-reentry, --frames); "
                          "huo2022: box-truth sequences after Huo et al. 2022's Table 1 (--sequence, --frames); "
                          "guler2016: a one-pixel target on a 100x100 14-bit wall after Güler's 2016 thesis, "
                          "134 frames at 100 Hz (--wall, --motion 1|2, --delta, --frames, --wall-seed)")
    sim.add_argument("--wall", choices=("S1", "S2"), default=None,
                     help="guler2016: the wall, S1 structured (mean 7195, σ ≈ 9.2 counts; default) or S2 smooth "
                          "(mean 8602, σ ≈ 4.3)")
    sim.add_argument("--wall-seed", type=number(whole, 0), default=None, metavar="N",
                     help="guler2016: draw the wall's static part (row profile and texture) from seed N, a whole "
                          "number ≥ 0 (default: the wall's one recording, seed 9 for S1 and 0 for S2, as the thesis "
                          "had one recording per sensor); --seed draws the drift and the noise")
    sim.add_argument("--delta", type=number(positive), default=None, metavar="D",
                     help="guler2016: the target pixel is set to the frame mean + D counts, D > 0 (default 30; the "
                          "thesis runs 100, 60, 50, 30, 20, 15, 14, 13, 10)")
    sim.add_argument("--case", choices=("5.1", "5.2", "5.3"), default=None,
                     help="long2012: 5.1 one CV target, 5.2 three manoeuvring targets (default), 5.3 three launches")
    sim.add_argument("--ptcr", type=number(positive, -20.0), default=None, metavar="DB",
                     help="bruno2008: peak target-to-clutter ratio 20·log10(max template / σ_c), dB, in (-20, 60] "
                          "(default 6.5; §4 also runs 8.1)")
    sim.add_argument("--exit-reentry", action="store_true",
                     help="bruno2008: the target runs until it leaves, 6 frames are empty, then a new target appears "
                          "(Figs. 1-5; at least 51 frames; not with --frames)")
    sim.add_argument("--snr-db", type=number(positive), default=None,
                     help="long2012: every target's peak SNR of Eq. 5, dB (default: the paper's)")
    sim.add_argument("--shape", type=number(whole, validate.MIN_SIDE), nargs=2, metavar=("H", "W"), default=None,
                     help="jia2022: frame height and width, px (each ≥ 8)")
    sim.add_argument("--frames", type=number(whole, 1), default=None,
                     help="jia2022: number of frames T (≥ 1); bruno2008: 3-10000 (default 20); huo2022: 2-5000 "
                          "(default 200); guler2016: 4-5000 (default 134)")
    sim.add_argument("--snr", type=number(positive), default=None,
                     help="jia2022: target SNR of Eq. 1: centre-pixel signal / noise std")
    sim.add_argument("--targets", type=number(whole, 1), default=None,
                     help="jia2022: number of targets (≥ 1, default 1); the other scenarios fix theirs")
    sim.add_argument("--seed", type=number(whole, 0), default=0,
                     help="random seed, a whole number ≥ 0 (default 0); guler2016: the drift and the noise only "
                          "(the wall is --wall-seed's)")
    sim.add_argument("--motion", choices=("stay", "transit", "1", "2"), default=None,
                     help="jia2022: stay, targets stay in view (default), or transit, they enter and leave; "
                          "guler2016: 1, from (x 0, y 69) rightwards (default), or 2, from (x 0, y 39) down-right at "
                          "45°, both 0.5 px/frame")
    sim.add_argument("--out", required=True, help="output .npz path (its folder must exist)")
    common(sim)
    sim.set_defaults(func=cmd_simulate, check=check_simulate)
