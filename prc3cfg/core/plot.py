"""Pictures of a module's motion (`prc3cfg.core.motion`): stroke profiles as SVG or PNG, and as mermaid.

- `picture(after, before=None, …)`: one subplot per chain, position (m) against time (s) from
  the reference point: turning points marked and numbered by program, dwell plateaus drawn
  thick, the upper reversing point S1 as a thin line, the time F1 and F2 are set as shaded
  bands. With `before` (what the module holds) the chains of both images are overlaid, before
  dashed grey (its outputs as hatched bands), after (what it will hold) in colour. The bytes
  are the same for the same images (and matplotlib): fixed sizes, a fixed SVG hash salt, no dates.
- `mermaid(before, after)`: one chain, before and after, as a ```mermaid xychart-beta``` block
  that GitHub renders, small enough for a pull request comment (`MERMAID_POINTS` per line).

matplotlib (prc3cfg's `plot` extra) is imported only by `plot_format` (which a command asking
for a picture calls before it reads anything: without it, it says so then) and `picture`, so this
module, and `mermaid`, work without it. What it says to install is matplotlib by its own name,
into the Python that runs prc3cfg (`missing_matplotlib`) — never `prc3cfg[plot]`: prc3cfg is not
on the package index, and whoever registers that name there would be installed by everyone who
followed the hint. Pure: images in, bytes or text out; the caller
writes the file.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

from prc3cfg.core.image import ModuleImage
from prc3cfg.core.motion import DWELL, ChainMotion, chain_motions, paired_chains
from prc3cfg.errors import UserError

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes

#: Output formats by file suffix.
FORMATS = {".svg": "svg", ".png": "png"}
#: What the `plot` extra installs, by its own name on the package index (pyproject.toml).
PLOT_PACKAGE = "matplotlib"
#: Fixed sizes: inches per subplot, and pixels per inch of a PNG.
WIDTH, CHAIN_HEIGHT, DPI = 9.0, 2.6, 100
AFTER, BEFORE = "#1f77b4", "#9e9e9e"
BANDS = {"F1": "#2ca02c", "F2": "#d62728"}
HATCHES = {"F1": "//", "F2": "\\\\"}
#: Values per line of a mermaid chart: a 0.2 s grid on a 10 s pass.
MERMAID_POINTS = 51


class PlotError(UserError):
    """A picture that cannot be made: no plotting library, an unknown format, nothing to draw."""


def missing_matplotlib(python: str) -> str:
    """What to do without matplotlib: install it into `python` (the Python that runs prc3cfg, as a
    command to paste into this system's shell) — matplotlib itself, never an extra of prc3cfg."""
    return (f"plotting needs {PLOT_PACKAGE}, which the Python running prc3cfg does not have — install it "
            f"there: {python} -m pip install {PLOT_PACKAGE}")


def plot_format(path: Path, *, python: str = "python") -> str:
    """"svg" or "png", by the file's suffix; PlotError for any other, and when matplotlib is missing
    (saying how to install it into `python`: see `missing_matplotlib`)."""
    fmt = FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise PlotError(f"{path}: a plot is drawn as SVG or PNG — name a file ending in .svg or .png")
    try:
        import matplotlib  # noqa: F401 — drawing will need it: say so before any time is spent
    except ImportError:
        raise PlotError(missing_matplotlib(python)) from None
    return fmt


def picture(after: ModuleImage, before: ModuleImage | None = None, *, fmt: str, title: str,
            python: str = "python") -> bytes:
    """The chains of `after` (and, overlaid, of `before`) drawn as `fmt` ("svg" or "png"); without
    matplotlib, a PlotError that says how to install it into `python`."""
    try:
        import matplotlib
        from matplotlib.figure import Figure
    except ImportError:
        raise PlotError(missing_matplotlib(python)) from None
    pairs = tuple((None, m) for m in chain_motions(after)) if before is None else paired_chains(before, after)
    if not pairs:
        raise PlotError(f"{title}: no chain to draw — a chain is programs linked by their jumps (chains: or "
                        "next: in the plant file)")
    with matplotlib.rc_context({"svg.hashsalt": "prc3cfg", "svg.fonttype": "path", "font.size": 8}):
        figure = Figure(figsize=(WIDTH, CHAIN_HEIGHT * len(pairs) + 0.5), dpi=DPI, layout="constrained")
        figure.suptitle(title, fontsize=10)
        for axes, (was, will) in zip(figure.subplots(len(pairs), 1, squeeze=False)[:, 0], pairs):
            _chain(axes, was, will, overlay=before is not None)
        drawn = {interval.output for pair in pairs for motion in pair if motion is not None
                 for interval in motion.outputs}
        figure.legend(handles=_legend(before is not None, drawn), loc="outside lower center", ncols=6,
                      frameon=False)
        out = io.BytesIO()
        figure.savefig(out, format=fmt, metadata={"Date": None} if fmt == "svg" else {"Software": None})
    return out.getvalue()


def _chain(axes: Axes, was: ChainMotion | None, will: ChainMotion | None, *, overlay: bool) -> None:
    shown = [m for m in (was, will) if m is not None]
    upper = max(m.upper for m in shown)
    for motion, colour, style in ((was, BEFORE, "--"), (will, AFTER, "-")):
        if motion is None or (motion is was and was == will):  # an unchanged chain is drawn once
            continue
        times, positions = zip(*motion.curve())
        axes.plot(times, positions, style, color=colour, linewidth=1.4)
        for s in motion.segments:
            if s.kind == DWELL and s.end > s.start:
                axes.plot([s.start, s.end], [s.end_position] * 2, color=colour, linewidth=4, alpha=0.6,
                          solid_capstyle="butt")
        for point in motion.turning_points:
            axes.plot(point.time, point.position, "o", color=colour, markersize=4,
                      fillstyle="full" if motion is will else "none")
            axes.annotate(str(point.program), (point.time, point.position), xytext=(3, 3),
                          textcoords="offset points", color=colour)
        for interval in motion.outputs:
            if motion is will:
                axes.axvspan(interval.start, interval.end, color=BANDS[interval.output], alpha=0.15,
                             linewidth=0)
            else:
                axes.axvspan(interval.start, interval.end, fill=False, hatch=HATCHES[interval.output],
                             edgecolor=BANDS[interval.output], alpha=0.35, linewidth=0)
    axes.axhline(upper, color="black", linewidth=0.6, linestyle=":")
    axes.annotate("S1", (0, upper), xytext=(2, -9), textcoords="offset points")
    axes.set_xlim(0, 1.03 * max(m.duration for m in shown) or 1.0)
    axes.set_ylim(0, upper * 1.08)
    axes.set_xlabel("time (s)")
    axes.set_ylabel("position (m)")
    axes.set_title(_caption(was, will, overlay=overlay), loc="left")


def _caption(was: ChainMotion | None, will: ChainMotion | None, *, overlay: bool) -> str:
    """ "chain 1 → 2 → 1, pass 10.15 s, cycle 9.85 s"; in a plan, before · after, or unchanged."""
    def times(motion: ChainMotion) -> str:
        cycle = f", cycle {motion.cycle_time:.2f} s" if motion.cycle_time is not None else ""
        return f"pass {motion.duration:.2f} s{cycle}"

    motion = will or was
    if motion is None:
        raise ValueError("a caption of no motion, before or after")
    if not overlay or was == will:
        return f"{motion.label}{' (unchanged)' if overlay else ''}: {times(motion)}"
    if was is None or will is None:
        return f"{motion.label} ({'new' if was is None else 'removed'}): {times(motion)}"
    if was.label == will.label:
        return f"{will.label}: before {times(was)} · after {times(will)}"
    return f"before {was.label}: {times(was)} · after {will.label}: {times(will)}"


def _legend(overlay: bool, outputs: set[str]) -> list[Artist]:
    """The legend of what is drawn: the bands of the function `outputs` that are set somewhere, no others."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [
        Line2D([], [], color=AFTER, label="after" if overlay else "position"),
        Line2D([], [], color=AFTER, linewidth=4, alpha=0.6, label="dwell"),
        Line2D([], [], color=AFTER, marker="o", linestyle="", markersize=4, label="turning point (program)"),
        *(Patch(color=colour, alpha=0.15, label=f"{output} set") for output, colour in BANDS.items()
          if output in outputs),
    ]
    if overlay:
        handles.insert(1, Line2D([], [], color=BEFORE, linestyle="--", label="before"))
    return handles


def mermaid(before: ChainMotion | None, after: ChainMotion | None) -> str:
    """One chain before (grey) and after (blue) as a mermaid xychart: both sampled on one time grid
    of `MERMAID_POINTS` values over the longer pass (a shorter pass stays where it ends)."""
    shown = [(m, colour, name) for m, colour, name in ((before, BEFORE, "before"), (after, AFTER, "after"))
             if m is not None]
    until = max(m.duration for m, _, _ in shown) or 1.0
    upper = max(m.upper for m, _, _ in shown)
    palette = ", ".join(colour for _, colour, _ in shown)
    passes = ", ".join(f"{name} {m.duration:.2f} s ({'grey' if colour == BEFORE else 'blue'})"
                       for m, colour, name in shown)
    lines = [
        "```mermaid",
        '%%{init: {"themeVariables": {"xyChart": {"plotColorPalette": "' + palette + '"}}}}%%',
        "xychart-beta",
        f'    title "{shown[-1][0].label} · pass: {passes}"',
        f'    x-axis "time (s)" 0 --> {_number(until)}',
        f'    y-axis "position (m)" 0 --> {_number(upper)}',
        *(f"    line [{', '.join(_number(x) for _, x in m.samples(MERMAID_POINTS, until))}]"
          for m, _, _ in shown),
        "```",
    ]
    return "\n".join(lines)


def _number(value: float) -> str:
    """Millimetres or hundredths of a second are enough for a chart: 2.0 → "2", 0.05 → "0.05"."""
    return f"{value:.3f}".rstrip("0").rstrip(".")
