"""Pictures of the image-in-the-loop run: rendered camera frames with the tracked poses drawn on them."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["plot_tracked_frames"]


def plot_tracked_frames(scenario, frames: Sequence, *, max_panels: int = 4, pad_um: float = 200.0, title: str = ""):
    """A figure of up to ``max_panels`` kept frames (:class:`stressbots.lab.plants.TrackedFrame`), each
    cropped to the robots, with the tracked bodies outlined (thick edge = front) and labelled."""
    from ..viz import _plt, draw_bodies, robot_colours

    plt = _plt()
    chosen = list(frames)
    if len(chosen) > max_panels:
        idx = np.unique(np.linspace(0, len(chosen) - 1, max_panels).round().astype(int))
        chosen = [chosen[i] for i in idx]
    k = max(len(chosen), 1)
    fig, axes = plt.subplots(1, k, figsize=(3.6 * k, 3.9), squeeze=False)
    colours = robot_colours(scenario.n)
    for ax, fr in zip(axes[0], chosen, strict=False):
        cal = fr.calibration
        rows, cols = fr.frame.shape
        (x0, x1), (y1, y0) = cal.to_um(np.array([-0.5, cols - 0.5]), np.array([-0.5, rows - 0.5]))
        ax.imshow(fr.frame, cmap="gray", vmin=0, vmax=255, extent=(x0, x1, y0, y1), origin="upper", interpolation="nearest")
        seen = np.all(np.isfinite(fr.tracked), axis=1)
        draw_bodies(ax, fr.tracked[seen], scenario.lengths_um[seen], scenario.widths_um[seen],
                    [colours[i] for i in np.flatnonzero(seen)], lw=1.2)
        for i in np.flatnonzero(seen):
            ax.annotate(scenario.names[i], fr.tracked[i, :2], color=colours[i], fontsize=7, ha="center", va="center")
        pts = [p[:, :2] for p in (fr.tracked, fr.true) if p is not None]
        allp = np.concatenate(pts)
        allp = allp[np.all(np.isfinite(allp), axis=1)]
        if len(allp):
            lo, hi = allp.min(axis=0) - pad_um, allp.max(axis=0) + pad_um
            span = max(hi - lo)
            mid = (lo + hi) / 2
            ax.set_xlim(mid[0] - span / 2, mid[0] + span / 2)
            ax.set_ylim(mid[1] - span / 2, mid[1] + span / 2)
        err = ""
        if fr.true is not None and seen.any():
            d = np.hypot(*(fr.true[seen, :2] - fr.tracked[seen, :2]).T)
            err = f", worst {d.max():.2g} um"
        ax.set_title(f"frame {fr.index}, t = {fr.time_s:.0f} s: {int(seen.sum())}/{scenario.n} found{err}", fontsize=8)
        ax.set_xlabel("x (um)", fontsize=7)
        ax.tick_params(labelsize=6)
    axes[0][0].set_ylabel("y (um)", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig
