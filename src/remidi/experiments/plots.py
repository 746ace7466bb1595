"""Plots: panels of training curves, mean ± std over seeds."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


@dataclass
class Curve:
    """One line: ``values`` f[S, T] over seeds and log points, drawn as mean ± std."""

    label: str
    steps: np.ndarray
    values: np.ndarray


@dataclass
class Panel:
    title: str
    curves: list[Curve]
    ylabel: str = ""
    xlabel: str = "step"
    references: list[tuple[float, str]] = field(default_factory=list)  # dashed horizontal lines


def plot_panels(path: Path, panels: list[Panel], title: str = "") -> None:
    """Save ``panels`` side by side into the PNG ``path``."""
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.0), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, panel in zip(axes[0], panels):
        for i, curve in enumerate(panel.curves):
            values = np.asarray(curve.values, dtype=float)
            mean, std = values.mean(axis=0), values.std(axis=0)
            color = colors[i % len(colors)]
            ax.plot(curve.steps, mean, label=curve.label, color=color)
            ax.fill_between(curve.steps, mean - std, mean + std, color=color, alpha=0.2, linewidth=0)
        for y, label in panel.references:
            ax.axhline(y, linestyle="--", color="grey", linewidth=1)
            ax.annotate(label, (1.0, y), xycoords=("axes fraction", "data"), ha="right", va="bottom",
                        fontsize=8, color="grey")
        ax.set_title(panel.title)
        ax.set_xlabel(panel.xlabel)
        ax.set_ylabel(panel.ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    _save(fig, path)


def plot_bars(path: Path, title: str, labels: list[str], series: dict[str, np.ndarray], ylabel: str = "",
              ylim: tuple[float, float] | None = None) -> None:
    """Grouped bar chart into the PNG ``path``: one group per label, one bar per series;
    ``series[name]`` f[len(labels), S] over seeds, drawn as mean with a ± std error bar."""
    fig, ax = plt.subplots(figsize=(min(14.0, max(6.0, 0.55 * len(labels) * max(1, len(series)) ** 0.5 + 2)), 4.2))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    width = 0.8 / max(1, len(series))
    x = np.arange(len(labels))
    for i, (name, values) in enumerate(series.items()):
        values = np.asarray(values, dtype=float)
        ax.bar(x + (i - (len(series) - 1) / 2) * width, values.mean(axis=1), width, yerr=values.std(axis=1),
               label=name, color=colors[i % len(colors)], capsize=2)
    ax.set_xticks(x, labels, rotation=35, ha="right", fontsize=8)
    ax.set_title(title)
    ax.set_ylabel(ylabel)
    if ylim is not None:
        ax.set_ylim(*ylim)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    _save(fig, path)


def _save(fig, path: Path) -> None:
    """Save atomically (temporary file, then rename) and close the figure."""
    fig.tight_layout()
    tmp = Path(path).with_name(f".{Path(path).name}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)
