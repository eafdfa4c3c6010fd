"""PNG plots of a run's output with matplotlib: history series, and particle snapshots.
A plot is written whole or not at all (to a temporary name, then renamed), and only to a
.png file."""

from __future__ import annotations

import contextlib
import math
import os

import numpy as np

from parsph.errors import InputError
from parsph.io.history import read_units
from parsph.io.results import file_kind, read_history, read_snapshots, snapshot_steps


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise InputError("plotting needs matplotlib: pip install matplotlib") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot(path: str, names: list, output: str | None, frames: int | None = None, limits=None) -> str:
    """Plot the run file `path` by what it holds: history series `names` (plot_history), or
    one snapshot field (plot_snapshots: `frames`, default 4, and `limits`); returns the PNG's
    path."""
    kind = file_kind(path)
    if kind == "history":
        if frames is not None or limits is not None:
            raise InputError(f"--frames and --limits apply to a plot of snapshots; {path} holds a history")
        return plot_history(path, names, output)
    if len(names) > 1:
        raise InputError(f"a plot of snapshots shows one field, got {len(names)}: {', '.join(names)}")
    return plot_snapshots(path, (names or ["J"])[0], 4 if frames is None else frames, output, limits)


def _output(output: str | None, default: str) -> str:
    """The PNG file to write: `output`, or `default`; InputError unless it names a .png
    file (never a directory or another kind of file, which the plot would replace)."""
    output = os.fspath(output or default)
    if not output.lower().endswith(".png"):
        raise InputError(f"the plot's output {output} must be a .png file")
    if os.path.isdir(output):
        raise InputError(f"the plot's output {output} is a directory")
    return output


def _save(plt, fig, output: str, **options) -> str:
    """Write `fig` to `output` whole (a temporary file renamed), close it; InputError
    naming the file if it cannot be written."""
    tmp = os.path.join(os.path.dirname(output) or ".", f".{os.path.basename(output)}.tmp")
    try:
        fig.savefig(tmp, format="png", **options)
        os.replace(tmp, output)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise InputError(f"the plot cannot be written to {output}: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)
    return output


def by_unit(names: list, units: dict) -> dict:
    """The series `names` grouped by their units, in order of first appearance."""
    panels = {}
    for n in names:
        panels.setdefault(units.get(n, ""), []).append(n)
    return panels


def plot_history(path: str, names: list, output: str | None) -> str:
    """Series `names` (default: the energies) against time, one panel per unit, each axis
    labelled with its unit."""
    data = read_history(path)
    units = read_units(path)
    names = names or [n for n in ("kinetic_energy", "strain_energy", "hourglass_energy", "total_energy")
                      if n in data]
    missing = [n for n in names if n not in data]
    if missing:
        raise InputError(f"no series {missing} in {path}; it has: {', '.join(sorted(data))}")
    output = _output(output, os.path.splitext(path)[0] + "_" + "_".join(names)[:80] + ".png")
    plt = _pyplot()
    panels = by_unit(names, units)
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 1.0 + 3.0 * len(panels)), sharex=True, squeeze=False)
    for ax, (unit, series) in zip(axes[:, 0], panels.items()):
        for n in series:
            ax.plot(data["time"], data[n], label=n)
        ax.set_ylabel(f"[{unit or '-'}]")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        ax.ticklabel_format(style="sci", scilimits=(-3, 4), useMathText=True)  # 2e-4, not 0.000200
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    return _save(plt, fig, output, dpi=120)


DRAWN = 200_000  # at most this many particles drawn per frame: more only overplot


def plot_snapshots(path: str, field: str, count: int, output: str | None, limits=None) -> str:
    """Particle clouds coloured by `field` at `count` times spread over the run (one: the
    last snapshot; 2D: x-y; 3D: x-z projection), on one scale, side by side, or one above
    the other for a body more than twice as wide as it is tall; at most DRAWN particles a
    frame (one in k by global id); in 1D the field against x, a curve per time."""
    if count < 1:
        raise InputError(f"--frames = {count}: give the number of snapshots to draw, at least 1")
    if limits is not None and not (all(map(math.isfinite, limits)) and limits[0] < limits[1]):
        raise InputError(f"--limits {limits[0]:g} {limits[1]:g}: give finite LOW < HIGH")
    output = _output(output, os.path.splitext(path)[0] + f"_{field}.png")
    steps = snapshot_steps(path)
    if not steps:
        raise InputError(f"{path} holds no snapshots")
    plt = _pyplot()
    first = 0 if count > 1 else len(steps) - 1  # one frame: the last
    pick = np.unique(np.linspace(first, len(steps) - 1, count).round().astype(int)).tolist()
    frames = [(s.time, s["position"], s[field]) for s in read_snapshots(path, ("position", field), which=pick)]
    values = [np.linalg.norm(v, axis=1) if v.ndim == 2 else v for _, _, v in frames]
    if all(np.ptp(x[:, 1:]) == 0 for _, x, _ in frames):  # a line of particles: profiles
        return _plot_profiles(plt, frames, values, field, output, limits)
    lo, hi = limits if limits else (min(v.min() for v in values), max(v.max() for v in values))
    vertical = 2 if np.ptp(frames[0][1][:, 2]) > 0 else 1
    extent = [max(np.ptp(x[:, k]) for _, x, _ in frames) for k in (0, vertical)]
    aspect = extent[0] / extent[1] if extent[1] > 0 else 1.0
    if aspect > 2.0:  # slender: a column of wide panels
        width = 9.0
        height = min(width / aspect, 3.0) + 0.6
        fig, axes = plt.subplots(len(frames), 1, figsize=(width + 1.5, height * len(frames)), squeeze=False)
        axes = axes[:, 0]
    else:
        size = (3.2 * len(frames), 4) if len(frames) > 1 else (6.4, 4.5)
        fig, axes = plt.subplots(1, len(frames), figsize=size, squeeze=False)
        axes = axes[0]
    span = [(min(x[:, k].min() for _, x, _ in frames), max(x[:, k].max() for _, x, _ in frames))
            for k in (0, vertical)]
    margin = [0.03 * (b - a) for a, b in span]
    for ax, (t, x, _), v in zip(axes, frames, values):
        every = -(-len(x) // DRAWN)  # a large cloud: every k-th particle (by global id)
        sc = ax.scatter(x[::every, 0], x[::every, vertical], c=v[::every], s=4, vmin=lo, vmax=hi, cmap="viridis")
        ax.set_xlim(span[0][0] - margin[0], span[0][1] + margin[0])  # one scale for every frame
        ax.set_ylim(span[1][0] - margin[1], span[1][1] + margin[1])
        ax.set_aspect("equal")
        ax.set_title(f"t = {t:.4g} s" + (f", one particle in {every}" if every > 1 else ""), fontsize=9)
        ax.tick_params(labelsize=7)
    fig.colorbar(sc, ax=list(axes), label=field, shrink=0.8)
    return _save(plt, fig, output, dpi=110)


def _plot_profiles(plt, frames: list, values: list, field: str, output: str, limits=None) -> str:
    """`field` against x at each time, in one panel (a 1D run's snapshots)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for (t, x, _), v in zip(frames, values):
        order = np.argsort(x[:, 0])
        ax.plot(x[order, 0], v[order], lw=1.2, label=f"t = {t:.4g} s")
    if limits:
        ax.set_ylim(*limits)
    ax.set_xlabel("x [m]")
    ax.set_ylabel(field)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(plt, fig, output, dpi=110)
