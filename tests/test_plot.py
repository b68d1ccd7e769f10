"""Pictures of the motion (`prc3cfg.core.plot`, `prc3cfg show --plot`): mermaid text, SVG and PNG files,
and the SVG opened in headless Chromium.

The files need matplotlib (the `plot` extra) and the browser test Debian's chromium: without
them those tests are skipped, saying what to install.
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from test_motion import TWO_PROGRAMS, image
from tools import needs, which
from typer.testing import CliRunner

import prc3cfg.cli.plant_commands  # noqa: F401  (registers the commands on `app`)
from prc3cfg import api
from prc3cfg.cli import app
from prc3cfg.core.image import ModuleImage, Program
from prc3cfg.core.motion import chain_motions, paired_chains
from prc3cfg.core.plot import MERMAID_POINTS, PlotError, mermaid, picture, plot_format

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "plants" / "demo-line.yaml"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: The known chain with program 1 lower and faster, and a new stopping chain 5 → 6.
CHANGED = TWO_PROGRAMS.with_programs({1: Program(P=1800, V=600, T=5, F1=1100, F2=1050, A=2),
                                      5: Program(P=1000, V=300, T=5, F1=1010, A=6),
                                      6: Program(P=400, V=300, T=20)})
#: A chain of six programs, looping: strokes up to 1.6, 1.8, 2.0 m and down to 0.2, 0.4, 0.6 m.
SIX_PROGRAMS = image(
    {n: Program(P=1500 + 100 * n if n % 2 else 100 * n, V=300 + 50 * n, T=5, F1=1050, F2=20, A=n % 6 + 1)
     for n in range(1, 7)},
    S1=2500, S2=50, S6=1200,
)


@pytest.fixture
def matplotlib():
    return pytest.importorskip("matplotlib",
                               reason="matplotlib is not installed: python -m pip install matplotlib")


def mermaid_values(text: str) -> list[list[float]]:
    lines = [line.strip() for line in text.splitlines() if line.strip().startswith("line [")]
    return [[float(v) for v in line[len("line [") : -1].split(", ")] for line in lines]


# -- mermaid -------------------------------------------------------------------------------------


def test_mermaid_draws_one_chain_before_and_after_in_a_few_hundred_characters():
    ((before, after),) = paired_chains(TWO_PROGRAMS, TWO_PROGRAMS.with_programs({1: CHANGED.program(1)}),
                                       changed_only=True)
    text = mermaid(before, after)
    lines = text.splitlines()
    assert lines[0] == "```mermaid" and lines[-1] == "```" and lines[2] == "xychart-beta"
    assert '"plotColorPalette": "#9e9e9e, #1f77b4"' in lines[1]  # before grey, after blue
    assert lines[3] == '    title "chain 1 → 2 → 1 · pass: before 10.15 s (grey), after 8.25 s (blue)"'
    assert lines[4] == '    x-axis "time (s)" 0 --> 10.15'
    assert lines[5] == '    y-axis "position (m)" 0 --> 2.5'
    was, will = mermaid_values(text)
    assert len(was) == len(will) == MERMAID_POINTS
    assert was[0] == will[0] == 0.05 and max(was) == 2 and max(will) == 1.8 and was[-1] == will[-1] == 0.2
    assert len(text) < 1000  # 2 programs: 937 characters


def test_mermaid_of_a_six_program_chain_is_as_small():
    (after,) = chain_motions(SIX_PROGRAMS)
    new = mermaid(None, after)
    assert '"plotColorPalette": "#1f77b4"' in new and len(mermaid_values(new)) == 1  # a new chain: after only
    higher = SIX_PROGRAMS.with_programs({3: Program(P=2200, V=600, T=5, F1=1050, F2=20, A=4)})
    ((before, after),) = paired_chains(SIX_PROGRAMS, higher, changed_only=True)
    assert len(mermaid(before, after)) < 1000  # 6 programs, before and after: 973 characters


# -- files ---------------------------------------------------------------------------------------


def test_svg_and_png_are_drawn_and_the_same_every_time(matplotlib, tmp_path):
    svg = picture(CHANGED, TWO_PROGRAMS, fmt="svg", title="module test: before (dashed) and after")
    png = picture(CHANGED, fmt="png", title="module test")
    assert svg == picture(CHANGED, TWO_PROGRAMS, fmt="svg", title="module test: before (dashed) and after")
    assert png == picture(CHANGED, fmt="png", title="module test")
    root = ET.fromstring(svg)
    assert root.tag == "{http://www.w3.org/2000/svg}svg" and b"<dc:date>" not in svg
    assert png.startswith(PNG_MAGIC)
    (tmp_path / "plan.svg").write_bytes(svg)
    (tmp_path / "chains.png").write_bytes(png)


def test_the_legend_names_only_the_output_bands_drawn(matplotlib):
    """A chain whose programs set F1 only has no "F2 set" in its legend (matplotlib writes each text as a
    comment)."""
    f1_only = TWO_PROGRAMS.with_programs({1: Program(P=1800, V=600, T=5, F1=1100, A=2)})
    svg = picture(f1_only, fmt="svg", title="module test")
    assert b"F1 set" in svg and b"F2 set" not in svg
    both = picture(CHANGED, TWO_PROGRAMS, fmt="svg", title="module test")
    assert b"F1 set" in both and b"F2 set" in both


def test_without_matplotlib_plotting_says_to_install_matplotlib_into_the_python_that_runs_prc3cfg(
    monkeypatch,
):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib → ImportError
    for draw in (lambda python: picture(TWO_PROGRAMS, fmt="svg", title="module test", python=python),
                 lambda python: plot_format(Path("a.svg"), python=python)):
        with pytest.raises(PlotError) as raised:
            draw("'/opt/python 3/bin/python3'")
        assert str(raised.value) == ("plotting needs matplotlib, which the Python running prc3cfg does "
                                     "not have — "
                                     "install it there: '/opt/python 3/bin/python3' -m pip install "
                                     "matplotlib")


def hinted_packages(hint: str) -> tuple[list[str], list[Requirement]]:
    """The command a hint says to run — `PYTHON -m pip install PACKAGE…` — as (the Python's argv, the
    packages)."""
    python, _, packages = hint.split("install it there: ", 1)[1].partition(" -m pip install ")
    return shlex.split(python), [Requirement(package) for package in shlex.split(packages)]


def test_the_hint_names_on_the_package_index_only_what_the_plot_extra_names_there(monkeypatch):
    """Never an extra of prc3cfg itself (`prc3cfg[plot]`): prc3cfg is not on the package index, and
    whoever registered that name there would be installed by everyone who followed the hint. Only
    the names the `plot` extra lists (each its own project's), into this very Python."""
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    extra = {canonicalize_name(Requirement(text).name)
             for text in pyproject["project"]["optional-dependencies"]["plot"]}
    assert extra == {"matplotlib"}
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(PlotError) as raised:
        api.plot_format(Path("a.svg"))  # as the command line asks
    python, packages = hinted_packages(str(raised.value))
    assert python == [sys.executable]
    assert packages and {canonicalize_name(p.name) for p in packages} <= extra and not any(p.extras
                                                                                           or p.url
                                                                                           for p in packages)
    assert "prc3cfg" not in str(raised.value).split(" -m pip install ", 1)[1]


def test_no_text_of_prc3cfg_says_to_install_prc3cfg_by_its_name_from_the_index():
    """The README, docs/ and the code: `pip install prc3cfg…` (with or without an extra) would fetch whatever
    holds that name on the index; a checkout (`-e '.[plot]'`) or a commit (`prc3cfg @ git+…`) is ours."""
    texts = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "prc3cfg").rglob("*.py")]
    by_name = re.compile(r"pip install[^\n`&;|]*?\s['\"]?prc3cfg(\[|['\"\s`]|$)", re.M)  # in one command
    assert not [f"{path.relative_to(ROOT)}: {m.group(0)}" for path in texts
                for m in by_name.finditer(path.read_text())]
    # it can fail
    assert by_name.search("python -m pip install 'prc3cfg[plot]'") and by_name.search("pip install prc3cfg")
    assert (not by_name.search("pip install -e '.[plot]'")
            and not by_name.search('pip install --no-deps "$PRC3CFG"'))
    assert not by_name.search("pip install . && prc3cfg plan")


def test_a_module_without_chains_and_an_unknown_format_are_one_line(matplotlib):
    with pytest.raises(PlotError,
                       match=r"^module test: no chain to draw — a chain is programs linked by their jumps"):
        picture(image({1: Program(P=300, V=100)}), fmt="svg", title="module test")
    assert plot_format(Path("a.SVG")) == "svg" and plot_format(Path("b.png")) == "png"
    with pytest.raises(PlotError,
                       match=r"^c\.pdf: a plot is drawn as SVG or PNG — name a file ending in \.svg "
                             r"or \.png$"):
        plot_format(Path("c.pdf"))


# -- the SVG in a browser ------------------------------------------------------------------------

CHROMIUM = which("chromium")


def open_in_chromium(svg: Path, out: Path) -> tuple[Path, str, list[str]]:
    """Open `svg` in headless Chromium: (its screenshot, the DOM it parsed, console lines)."""
    screenshot = out / f"{svg.stem}-screenshot.png"
    done = subprocess.run(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         f"--user-data-dir={out / 'chromium-profile'}", "--enable-logging=stderr", "--v=0",
         "--window-size=1000,800", f"--screenshot={screenshot}", "--dump-dom", svg.as_uri()],
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return screenshot, done.stdout, [line for line in done.stderr.splitlines() if ":CONSOLE" in line]


@needs("chromium")
def test_the_svg_opens_in_headless_chromium_without_errors(matplotlib, tmp_path):
    svg = tmp_path / "plot.svg"
    svg.write_bytes(picture(CHANGED, TWO_PROGRAMS, fmt="svg", title="module test: before (dashed) and after"))
    screenshot, dom, console = open_in_chromium(svg, tmp_path)
    assert screenshot.read_bytes().startswith(PNG_MAGIC) and screenshot.stat().st_size > 10_000
    assert "<svg" in dom and "parsererror" not in dom
    assert console == []


@needs("chromium")
def test_the_browser_check_sees_a_broken_svg_and_console_errors(tmp_path):
    """The check itself can fail: a damaged SVG gives a parser error page, a script a console line."""
    broken, noisy = tmp_path / "broken.svg", tmp_path / "noisy.svg"
    broken.write_text('<svg xmlns="http://www.w3.org/2000/svg"><rect width="9" height="9"></svg>')
    noisy.write_text('<svg xmlns="http://www.w3.org/2000/svg"><script>console.error("boom")</script></svg>')
    assert "parsererror" in open_in_chromium(broken, tmp_path)[1]
    assert any('"boom"' in line for line in open_in_chromium(noisy, tmp_path)[2])


# -- the command line ----------------------------------------------------------------------------

runner = CliRunner()


def test_show_plot_draws_the_plant_files_chains_and_overlays_a_read_back(matplotlib, tmp_path):
    svg, png = tmp_path / "top.svg", tmp_path / "top.png"
    result = runner.invoke(app, ["show", str(DEMO), "--module", "booth-a-top", "--plot", str(svg)])
    assert result.exit_code == 0, result.stderr
    assert result.stdout == f"{svg}: the chains of module booth-a-top\n"
    assert ET.parse(svg).getroot().tag == "{http://www.w3.org/2000/svg}svg"
    actual = tmp_path / "read.json"
    actual.write_text(json.dumps([{"bus": "booth-a", **ModuleImage.factory(5).to_json()}]))  # no chains yet
    result = runner.invoke(app, ["show", str(DEMO), "-m", "booth-a-top", "--plot", str(png), "--actual",
                                 str(actual)])
    assert result.exit_code == 0, result.stderr
    assert png.read_bytes().startswith(PNG_MAGIC)


@pytest.mark.parametrize(("args", "message"), [
    (["--module", "booth-a-top", "--plot", "top.pdf"],
     "error: top.pdf: a plot is drawn as SVG or PNG — name a file ending in .svg or .png"),
    (["--plot", "top.svg"], "error: --plot draws one module — name it with --module NAME"),
    (["--module", "booth-a-top", "--actual", "read.json"],
     "error: --actual is what --plot overlays — give --plot FILE.svg or FILE.png too"),
    (["--module", "booth-a-top", "--plot", "missing/top.svg"],
     "error: --plot missing/top.svg: the folder missing does not exist — create it, or name a file in an "
     "existing folder"),
])
def test_show_plot_mistakes_are_one_line_before_any_work(args, message, tmp_path):
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "show", str(DEMO), *args],
                          capture_output=True, text=True, cwd=tmp_path)
    assert (done.returncode, done.stderr, done.stdout) == (1, message + "\n", "")


def test_plan_plot_draws_the_module_before_and_after_its_plan(matplotlib, tmp_path, capsys):
    """`plan --module NAME --plot FILE` draws what the module holds (dashed) and what the plan leaves,
    from the same read-back as the plan — the drawing `api.picture` makes of those images."""
    from emulated import emulated_plant, run_cli

    from prc3cfg import api

    svg = tmp_path / "top.svg"
    with emulated_plant(tmp_path) as emulated:
        result = run_cli(capsys, "plan", emulated.path, "--module", "booth-a-top", "--plot", svg)
        assert result.code == 0, result.err
        assert result.out.endswith(f"{svg}: the chains of module booth-a-top\n")
        held = {key: image for key, image in emulated.images().items() if key == ("booth-a", 5)}
        assert svg.read_bytes() == api.picture(emulated.plant, "booth-a-top", fmt="svg", images=held)
