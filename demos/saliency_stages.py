"""Figure of the saliency stages on one simulated frame at SNR 1.4 (like SGDS-PF Figs. 4–6).

Panels: the raw frame, I_se (Eq. 21), I_acc2 (Eq. 22), the segmentation mask I_rt
(Eq. 24), the saliency Sal (Eq. 29, normalised per block) and the per-block proposal
map OPsal_N (Eq. 33) with the block edges.  The true target is circled.

    python demos/saliency_stages.py [--out docs/saliency_stages.png] [--seed 3]
"""
import argparse
from pathlib import Path

import cv2

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import tbd_taichi as tbd  # noqa: E402
from tbd_taichi.saliency import saliency_stages  # noqa: E402


def dilate(img: np.ndarray) -> np.ndarray:
    """3×3 grey dilation, so that single-pixel values are visible at figure size."""
    return cv2.dilate(np.asarray(img, np.float32), np.ones((3, 3), np.uint8))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/saliency_stages.png", help="output PNG")
    parser.add_argument("--seed", type=int, default=3, help="simulation seed")
    parser.add_argument("--snr", type=float, default=1.4, help="target SNR (Eq. 1) and the snr preset")
    args = parser.parse_args()

    scene = tbd.simulate((200, 200), frames=11, snr=args.snr, seed=args.seed)
    z = tbd.normalize.normalise_sequence(scene.frames)
    f = 5
    maps = saliency_stages(z, f, snr=args.snr, block_size=100)
    t = scene.truth[scene.truth["frame"] == f][0]
    panels = [("raw frame z", maps["z"], "gray"), ("I_se (Eq. 21)", maps["I_se"], "magma"),
              ("I_acc2 (Eq. 22)", maps["I_acc2"], "magma"), ("mask I_rt (Eq. 24)", maps["I_rt"], "gray"),
              ("saliency (Eq. 29), dilated 3x3", dilate(maps["saliency"]), "viridis"),
              ("proposal OPsal_N (Eq. 33), dilated 3x3", dilate(maps["proposal"]), "viridis")]
    fig, axes = plt.subplots(2, 3, figsize=(13, 8.6))
    edges = np.flatnonzero(np.diff(maps["block_id"][0])) + 0.5, np.flatnonzero(np.diff(maps["block_id"][:, 0])) + 0.5
    for ax, (title, img, cmap) in zip(axes.ravel(), panels):
        ax.imshow(img, cmap=cmap, interpolation="nearest")
        ax.add_patch(plt.Circle((t["x"], t["y"]), 5, fill=False, color="red", lw=1.2))
        for x in edges[0]:
            ax.axvline(x, color="cyan", lw=0.6, alpha=0.7)
        for y in edges[1]:
            ax.axhline(y, color="cyan", lw=0.6, alpha=0.7)
        ax.set_title(title)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"SGDS-PF saliency stages, 200x200, SNR {args.snr}, frame {f}; red circle: target; cyan: blocks")
    fig.tight_layout()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=70)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
