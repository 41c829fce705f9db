"""The figures of the ``long2012`` suite (:mod:`tbd_taichi.suite_long2012`), after Long et al. 2012's Figs. 2, 4, 5
and 7: OSPA (c = 5 px, p = 2) and position RMSE (Eq. 38) by frame, and Eq. 35's model probabilities by frame.
Frames on the axes are the paper's (1-based)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .motion_models import MODELS


def _mean_ospa(results: list[dict]) -> np.ndarray:
    return np.mean([r["ospa"] for r in results], axis=0)


def _axes(n: int, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.4), squeeze=False)
    fig.suptitle(title)
    return fig, axes[0]


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


def fig2(results: list[dict], out: Path) -> Path:
    """§5.1: mean OSPA and RMSE by frame, standard against improved SMC-PHD, at 12, 10 and 8 dB."""
    from .suite_long2012 import FIG2_SNRS, _select, rmse_by_frame

    fig, (a, b) = _axes(2, "Fig. 2: standard vs improved SMC-PHD (§5.1)")
    for db, colour in zip(FIG2_SNRS, ("C0", "C1", "C2")):
        for variant, style in (("standard", "--"), ("smc-phd", "-")):
            sel = _select(results, "5.1", variant, db)
            if not sel:
                continue
            label = f"{'improved' if variant == 'smc-phd' else 'standard'} {db:g} dB"
            a.plot(np.arange(1, len(sel[0]["ospa"]) + 1), _mean_ospa(sel), style, color=colour, label=label)
            frames, err = rmse_by_frame(sel, 0)
            b.plot(frames + 1, err, style, color=colour, label=label)
    a.set(xlabel="frame", ylabel="OSPA (px)")
    b.set(xlabel="frame", ylabel="RMSE (px)")
    a.legend(fontsize=7)
    return _save(fig, out / "long2012_fig2.png")


def fig4(results: list[dict], out: Path) -> Path:
    """§5.2: MM-PHD's mean OSPA by frame and each target's RMSE by frame."""
    from .suite_long2012 import _select, rmse_by_frame

    sel = _select(results, "5.2", "mm-phd")
    fig, (a, b) = _axes(2, "Fig. 4: MM-PHD on §5.2")
    a.plot(np.arange(1, len(sel[0]["ospa"]) + 1), _mean_ospa(sel))
    a.set(xlabel="frame", ylabel="OSPA (px)")
    for t in sorted(sel[0]["truth_frames"]):
        frames, err = rmse_by_frame(sel, t)
        b.plot(frames + 1, err, label=f"target {int(t) + 1}")
    b.set(xlabel="frame", ylabel="RMSE (px)")
    b.legend(fontsize=7)
    return _save(fig, out / "long2012_fig4.png")


def fig5(results: list[dict], out: Path) -> Path:
    """§5.2: each target's mean model probabilities (Eq. 35) by frame over the runs with a row, the true model
    below as a band."""
    from .suite_long2012 import _select

    sel = _select(results, "5.2", "mm-phd")
    targets = sorted(sel[0]["truth_frames"])
    fig, axes = _axes(len(targets), "Fig. 5: model probabilities (Eq. 35) on §5.2")
    names = sel[0]["model_names"]
    for ax, t in zip(axes, targets):
        frames = np.array(sel[0]["truth_frames"][t]) + 1
        probs = np.array([[np.full(len(names), np.nan) if p is None else p for p in r["model_probs"][t]]
                          for r in sel], float)
        seen = np.isfinite(probs).any(axis=0)
        mean = np.where(seen, np.nansum(probs, axis=0) / np.maximum(np.isfinite(probs).sum(axis=0), 1), np.nan)
        for j, name in enumerate(names):
            ax.plot(frames, mean[:, j], label=name)
        truth = np.array(sel[0]["truth_models"][t])
        for j, name in enumerate(names):
            on = truth == MODELS.index(name)
            ax.fill_between(frames, -0.08, -0.02, where=on, step="mid", color=f"C{j}", alpha=0.6)
        ax.set(xlabel="frame", ylabel="P_r", ylim=(-0.1, 1.05), title=f"target {int(t) + 1} (band: true model)")
        ax.legend(fontsize=7)
    return _save(fig, out / "long2012_fig5.png")


def fig7(results: list[dict], out: Path) -> Path:
    """§5.3: mean OSPA by frame, MM-PHD against SMC-PHD."""
    from .suite_long2012 import _select

    fig, (a,) = _axes(1, "Fig. 7: OSPA on §5.3")
    for variant in ("mm-phd", "smc-phd"):
        sel = _select(results, "5.3", variant)
        if sel:
            a.plot(np.arange(1, len(sel[0]["ospa"]) + 1), _mean_ospa(sel), label=variant.upper())
    a.set(xlabel="frame", ylabel="OSPA (px)")
    a.legend(fontsize=7)
    return _save(fig, out / "long2012_fig7.png")


def plot_figures(results: list[dict], out: Path) -> list[Path]:
    """Figs. 2, 4, 5 and 7 as PNG files in ``out``."""
    return [f(results, out) for f in (fig2, fig4, fig5, fig7)]
