"""Figures of the paper's kinds, written atomically as PNG (matplotlib, Agg).

Units: mm on map axes, µm for sag and detector offsets.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from pipeline.io.common import atomic_path  # noqa: E402

__all__ = ["plot_sag_maps", "plot_line_profiles", "plot_psfs", "plot_multigrating", "save"]


def save(fig, path: Path) -> Path:
    """Write ``fig`` to ``path`` atomically (temp file + rename) and close it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path


def plot_sag_maps(maps: list, titles: list[str], path: Path, box_mm=(82.0, 72.0)) -> Path:
    """Sag maps side by side on one colour scale (µm), with the central P/V box."""
    vals = np.concatenate([m.sag_um[np.isfinite(m.sag_um)] for m in maps])
    lim = np.percentile(np.abs(vals - np.median(vals)), 99.9)
    fig, axes = plt.subplots(1, len(maps), figsize=(4.6 * len(maps), 4.2), squeeze=False)
    for ax, m, title in zip(axes[0], maps, titles):
        c = np.nanmedian(m.sag_um)
        im = ax.imshow(m.sag_um - c, origin="lower", cmap="RdBu_r", vmin=-lim, vmax=lim,
                       extent=(m.x_mm[0], m.x_mm[-1], m.y_mm[0], m.y_mm[-1]))
        ax.add_patch(Rectangle((-box_mm[0] / 2, -box_mm[1] / 2), *box_mm, fill=False, ec="k", lw=1.2, ls="--"))
        ax.set_title(f"{title}\nP/V$_{{center}}$ = {m.pv_um('center'):.2f} µm", fontsize=10)
        ax.set_xlabel("x (dispersion) [mm]")
        ax.set_ylabel("y (grooves) [mm]")
    fig.colorbar(im, ax=axes[0].tolist(), label="sag − median [µm]", shrink=0.85)
    return save(fig, path)


def plot_line_profiles(panels: dict, path: Path, slit_um: float = 27.0) -> Path:
    """Grid of detected line profiles: panels[(row_label, col_label)] = [(label, Profile), ...]."""
    rows = list(dict.fromkeys(k[0] for k in panels))
    cols = list(dict.fromkeys(k[1] for k in panels))
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(3.6 * len(cols), 2.8 * len(rows)),
                             squeeze=False, sharex=True)
    for i, r in enumerate(rows):
        for j, c in enumerate(cols):
            ax = axes[i, j]
            for label, prof in panels.get((r, c), []):
                ax.plot(prof.offset_um, prof.intensity, label=label, lw=1.3)
            for s in (-slit_um / 2, slit_um / 2):
                ax.axvline(s, color="0.5", ls=":", lw=0.8)
            ax.set_xlim(-80, 80)
            ax.set_title(f"{r} — {c}", fontsize=9)
            if i == len(rows) - 1:
                ax.set_xlabel("detector offset [µm]")
            if j == 0:
                ax.set_ylabel("intensity [1/µm]")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    return save(fig, path)


def plot_psfs(psfs: list, titles: list[str], path: Path, window_um: float = 80.0) -> Path:
    """Point-source PSFs (log scale) on the detector."""
    fig, axes = plt.subplots(1, len(psfs), figsize=(4.2 * len(psfs), 4.0), squeeze=False)
    for ax, p, t in zip(axes[0], psfs, titles):
        I = p.intensity / p.intensity.max()
        ax.imshow(np.log10(np.maximum(I, 1e-4)), origin="lower", cmap="magma", vmin=-4, vmax=0,
                  extent=(p.offset_x_um[0], p.offset_x_um[-1], p.offset_y_um[0], p.offset_y_um[-1]))
        ax.set_xlim(-window_um, window_um)
        ax.set_ylim(-window_um, window_um)
        ax.set_title(t, fontsize=9)
        ax.set_xlabel("x (spectral) [µm]")
        ax.set_ylabel("y (along slit) [µm]")
    fig.tight_layout()
    return save(fig, path)


def plot_multigrating(profiles: list, path: Path,
                      title: str = "1.25 µm line on the J, H and K gratings (250 mas)") -> Path:
    """Several profiles in one panel, e.g. one wavelength on several gratings: [(label, Profile), ...]."""
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for label, prof in profiles:
        ax.plot(prof.offset_um, prof.intensity, label=label, lw=1.4)
    ax.set_xlim(-80, 80)
    ax.set_xlabel("detector offset [µm]")
    ax.set_ylabel("intensity [1/µm]")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)
