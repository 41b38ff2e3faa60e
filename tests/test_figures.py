"""Figures quoted on several pages agree with the one measured table they come from (issue 27, item 7).

A quantity measured once (a speed-up between devices, a run time, a memory figure, an agreement
bound) has ONE source page: the page with the measured table, its command, setting and machine.
Any other page (README.md, docs/*.md, the command line's help texts) that gives a figure of that
quantity must give the source's figure and name the source page (a link or the path) in the same
paragraph or list item; a mention without a figure needs no link. So a re-measured table cannot leave
an older figure behind on another page unnoticed.

Each :class:`Quantity` has a ``mention`` regex with a named group ``fig`` (the figure, when the mention
gives one), matched on each paragraph with its whitespace collapsed; ``allowed`` lists the figures the
source measured; ``source_has`` are regexes the source page must still match (the table rows behind
the figures). A few figures are also checked against the code or the source's own table.
A new quantity is one more entry; a reworded mention that no longer matches is a mention the test no
longer sees, so keep ``mention`` loose (the figure, a short gap, the phrase).
"""
from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # a source checkout: bench/report/ beside pyclpt/
    sys.path.insert(0, str(REPO))

X = r"\d+(?:\.\d+)?(?:\s*[-–]\s*\d+(?:\.\d+)?)?\s*(?:x|×|times)(?!\w)"  # 1.22x, 1.2-1.6x, 2.4 times
TIME = (r"\d+(?:\.\d+)?(?:\s*[-–]\s*\d+(?:\.\d+)?)?\s*(?:s|seconds?|min|minutes?)(?!\w)"  # 43 s, 0.8-5.8 s
        r"|(?:a|one|two|three|a few)\s+(?:seconds?|minutes?)|an? (?:second|minute|hour)")  # about two minutes


@dataclass(frozen=True)
class Quantity:
    name: str
    source: str                       # repository path of the page holding the measured table
    source_has: tuple[str, ...]       # regexes the source page matches (whitespace collapsed)
    mention: str                      # regex of a mention on another page; group "fig": its figure
    allowed: tuple[str, ...]          # the source's figures, as a mention may write them

    def normal(self, fig: str) -> str:
        return re.sub(r"\s+", " ", fig.replace("–", "-")).strip()


QUANTITIES = (
    Quantity("Intel's CPU runtime against PoCL (Cornell box, 256x256, 64 spp, depth 8)", "docs/devices.md",
             (r"\| Intel OpenCL [\d.]+ \| megakernel \|[^\n]*\| 1\.22x \|",
              r"\| Intel OpenCL [\d.]+ \| wavefront SoA \|[^\n]*\| 1\.61x \|"),
             rf"(?P<fig>{X})[^.]{{0,60}}?(?:as fast|PoCL's speed|faster than PoCL|PoCL's rate)",
             ("1.22x", "1.61x", "1.2-1.6x")),
    Quantity("run time of `pyclpt bench --quick`", "docs/benchmarks.md",
             (r"`pyclpt bench --quick -o quick` [^\n]*? took 43 s wall",),
             rf"(?:bench --quick|--quick small settings)(?:[^.;]{{0,80}}?(?P<fig>{TIME}))?",
             ("43 s",)),
    Quantity("compile time of the README's first command, cold and after `pyclpt warmup`", "docs/getting-started.md",
             (r"\| `--spp 64` \(the README's first command, 256×256\) \| Intel \| 0\.81 s → 0\.09 s \|",
              r"\| `--spp 64` \(256×256\) \| PoCL \| 1\.92 s → 0\.15 s \|"),
             r"(?:compile[^.|]{0,40}?from|\band from) (?P<fig>\d+(?:\.\d+)? s to \d+(?:\.\d+)? s)",
             ("0.81 s to 0.09 s", "1.92 s to 0.15 s")),
    Quantity("cold compile time of a built-in scene's kernels", "docs/getting-started.md",
             (r"\| command \(`pyclpt render cornell-box \.\.\.`\) \| device \| compile cold → after warmup \|",),
             rf"compil\w+ the megakernel[^.]{{0,60}}? takes (?P<fig>{TIME})",
             ("0.8-5.8 s",)),
    Quantity("wavefront path state per path", "docs/wavefront.md",
             (r"31 words = 124 bytes per path",
              r"124 bytes of state \+ 24 bytes of queue entries \(six int queues\) \+ 1 flag byte = 149 bytes"),
             r"(?P<fig>\d+) bytes (?:per path|of (?:path )?state)",
             ("124", "149")),
    Quantity("wavefront SoA against its megakernel in the runs against Mitsuba 3 (depth 65)", "docs/benchmarks.md",
             (r"The wavefront SoA runs at 1\.01x / 0\.97x \(Intel; [^)]*\) and 0\.87x / 0\.93x \(PoCL\) of its "
              r"megakernel",),
             rf"wavefront SoA (?:now )?runs at (?P<fig>{X})",
             ("0.97x", "0.93x", "1.01x", "0.87x")),
    Quantity("8-wide BVH against the binary BVH, whole renders", "docs/bvh.md",
             (r"1\.3-1\.8x on whole renders",),
             rf"(?:8-wide BVH|BVH8) gave (?:PoCL )?(?P<fig>{X})",
             ("1.3-1.8x",)),
    Quantity("distributed render against the single-machine image", "docs/distributed.md",
             (r"within 1e-12 relative",),
             r"within (?P<fig>\d+(?:\.\d+)?e-\d+) relative",
             ("1e-12",)),
)


def collapse(text: str) -> str:
    return re.sub(r"\s+", " ", text).strip()


def paragraphs(text: str) -> list[str]:
    """Paragraphs (blank-line separated), list items apart, whitespace collapsed."""
    out = []
    for para in re.split(r"\n\s*\n", text):
        out += [collapse(item) for item in re.split(r"\n(?=\s*(?:[-*]|\d+\.) )", para) if item.strip()]
    return out


def _help_texts() -> dict[str, str]:
    """Every help text of the command line: ``pyclpt``, each subcommand, ``pyclpt bench`` (and --versus)."""
    from bench.report import report, versus
    from pyclpt.cli import build_parser

    top = build_parser()
    texts = {"pyclpt --help": top.format_help()}
    for action in top._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                texts[f"pyclpt {name} --help"] = sub.format_help()
    texts["pyclpt bench --help"] = report.build_parser().format_help()
    texts["pyclpt bench --versus mitsuba --help"] = versus.build_parser().format_help()
    return texts


def pages() -> dict[str, str]:
    docs = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
    out = {p.relative_to(REPO).as_posix(): p.read_text(encoding="utf-8") for p in docs}
    out.update(_help_texts())
    return out


PAGES = pages()


@pytest.mark.parametrize("q", QUANTITIES, ids=lambda q: q.name)
def test_source_page_holds_the_measured_figures(q: Quantity) -> None:
    text = collapse(PAGES[q.source])
    for pattern in q.source_has:
        assert re.search(pattern, text), f"{q.source} no longer matches {pattern!r} ({q.name})"


@pytest.mark.parametrize("q", QUANTITIES, ids=lambda q: q.name)
def test_other_pages_quote_the_source(q: Quantity) -> None:
    """A figure of the quantity elsewhere is the source's and names the source page beside it."""
    source_name = Path(q.source).name
    problems = []
    for page, text in PAGES.items():
        if page == q.source:
            continue
        for para in paragraphs(text):
            for m in re.finditer(q.mention, para, re.IGNORECASE):
                fig = m.group("fig")
                if fig is None:
                    continue
                where = f"{page}: {para[max(0, m.start() - 40):m.end() + 40]!r}"
                if q.normal(fig) not in q.allowed:
                    problems.append(f"{where}: {fig!r} is not among {q.source}'s figures {q.allowed}")
                if source_name not in para:
                    problems.append(f"{where}: gives a figure without naming {q.source}")
    assert not problems, f"{q.name}:\n" + "\n".join(problems)


def test_mentions_are_seen() -> None:
    """Each quantity's mention pattern still finds a figure outside its source (else it checks nothing)."""
    for q in QUANTITIES:
        found = [page for page, text in PAGES.items() if page != q.source
                 for para in paragraphs(text) for m in re.finditer(q.mention, para, re.IGNORECASE)
                 if m.group("fig")]
        assert found, f"no page quotes {q.name!r} any more: drop it from QUANTITIES or fix its mention regex"


def test_path_state_figures_match_the_code() -> None:
    from pyclpt.integrators.path_state import bytes_per_path
    from pyclpt.integrators.wavefront import QUEUE_BYTES_PER_PATH

    assert bytes_per_path() == 124
    assert bytes_per_path() + QUEUE_BYTES_PER_PATH == 149


def test_bvh_whole_render_range_matches_its_table() -> None:
    """docs/bvh.md's "1.3-1.8x on whole renders" is the range of w8 / w2 in its whole-render table."""
    text = PAGES["docs/bvh.md"]
    table = text.split("Whole-render speed of the megakernel", 1)[1].split("\n\n", 2)[1]
    ratios = []
    for row in table.splitlines()[2:]:
        cells = [c.strip() for c in row.strip("|").split("|")]
        ratios.append(float(cells[3]) / float(cells[1]))
    stated = re.search(r"(\d\.\d)-(\d\.\d)x on whole renders", text)
    assert stated and (float(stated[1]), float(stated[2])) == (round(min(ratios), 1), round(max(ratios), 1)), ratios


def test_cold_compile_range_matches_its_table() -> None:
    """docs/scenes.md's cold compile range is the range of the cold column of getting-started.md's table."""
    rows = re.findall(r"^\| [^|]+ \| (?:Intel|PoCL) \| (\d+\.\d+) s → ", PAGES["docs/getting-started.md"], re.MULTILINE)
    cold = [float(r) for r in rows]
    assert len(cold) >= 4, rows
    assert f"{round(min(cold), 1)}-{round(max(cold), 1)} s" == "0.8-5.8 s", cold
