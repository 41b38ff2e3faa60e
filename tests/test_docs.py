"""Documentation that cannot rot: every example in README.md and docs/**/*.md runs as written.

What runs
  Every fenced code block whose info string is ``sh``, ``bash``, ``console`` or ``python``, one test per
  block, named after its file and the line of its opening fence (``test_doc_block[README.md:L42]``).
  Blocks that are not meant to run (program output, file formats, trees) take another info string
  (``text``, ``json``, ``xml``, ...); a fenced block without an info string is an error, and so is a
  non-running block that starts like a command (``pyclpt ...``, ``python ...``, ``import ...``).

  - ``python`` blocks run in one fresh interpreter per Markdown file, in the file's order, sharing
    their globals as a notebook does: a block may use what an earlier block of the same page defined
    (run alone with ``-k``, a block first runs the earlier blocks of its page). Tracebacks name the
    Markdown file and its line.
  - ``sh`` / ``bash`` blocks run with ``bash -euo pipefail``; ``console`` blocks run their ``$ `` lines.
  - Every block of a file runs in one temporary working folder (output files land there), which
    holds a link ``bench`` to the checkout's ``bench/`` (for "from a checkout" commands such as
    ``python -m bench.tools.gallery``) and has ``../shared/scenes`` linked to the shared scene folder.
    ``pyclpt``, ``python`` and ``python3`` on ``PATH`` are this Python's, ``PYCLPT_SCENES`` names the
    shared scene folder, and ``PYCLPT_CACHE_DIR`` is the test session's.
  - A block that needs the shared scene folder (it mentions ``shared/scenes`` or ``PYCLPT_SCENES``,
    or a built-in scene that reads from it, e.g. ``cornell-bunny``) is skipped when
    :func:`pyclpt.scene.library.scenes_root` finds none. Such a block should not define names that
    later blocks of its page use.

Annotations
  An HTML comment on the line(s) right above the opening fence (invisible on a rendered page) changes
  how the test runs the block; nothing else may::

      <!-- test: replace "--spp 64" "--spp 2"; replace "--width 640 --height 360" "--width 32 --height 18" -->
      <!-- test: skip installs into a fresh virtual environment (tests/test_install.py and CI run it) -->
      <!-- test: needs-scenes -->

  - ``replace "OLD" "NEW"``: run the block with every OLD replaced by NEW (quoted as in a shell; the
    only way to shrink a long-running example: small images, 1-4 spp). OLD must occur in the block,
    and NEW may not add lines (tracebacks keep the file's line numbers).
  - ``skip REASON``: not run; the reason is required and the directive stands alone.
  - ``needs-scenes``: skipped without the shared scene folder (when the automatic detection misses it).
  Directives are separated by ``;``; several comment lines may be stacked. An illustrative fragment
  (code to add to a module, not a runnable example) keeps its ``python`` highlighting with
  ``<!-- test: skip fragment of pyclpt/scene/model.py -->``.

  A page that names files to create (a walkthrough) lists them, anywhere in the page, with
  ``<!-- test: example-paths cl/scene/bsdfs/roughdiffuse.h ... -->``: the paths test below skips them.

Also tested here: every ``pyclpt.X`` name used in the docs (code blocks and inline code) resolves,
and a documented top-level name is in ``pyclpt.__all__`` (the public API, issue 10 item 4; one test
per name); every ``Name.attr`` of a public class exists; every class named in inline code is public
or defined in pyclpt's, bench's or the OpenCL sources; every repository path in inline code exists;
every relative link points at an existing file and heading.

Blocks run with ``PYCLPT_DOCS_TEST=1``, under which this module skips itself, so a documented
``pytest`` command cannot recurse (a block running the test suite still needs a ``skip``).

The whole module should stay under about two minutes on two cores: documented examples are
realistic, and their annotations shrink them here.
"""
from __future__ import annotations

import builtins
import dataclasses
import importlib
import importlib.util
import json
import os
import re
import select
import shlex
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import pyclpt
from pyclpt.scene.library import builtin_dir, scenes_root

REPO = Path(__file__).resolve().parent.parent
RUNNABLE = {"sh": "shell", "bash": "shell", "console": "console", "python": "python"}
BLOCK_TIMEOUT_S = 300
# Set in the blocks' environment: a documented `pytest` must not run this module again.
GUARD = "PYCLPT_DOCS_TEST"

if os.environ.get(GUARD):
    pytest.skip("running inside a documentation example", allow_module_level=True)


def shared_scenes() -> Path | None:
    """The shared scene folder if it exists (PYCLPT_SCENES, ../shared/scenes), else None."""
    root = scenes_root()
    return Path(root).resolve() if root is not None and Path(root).is_dir() else None


def doc_files() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def rel(path: Path) -> str:
    return path.relative_to(REPO).as_posix() if path.is_relative_to(REPO) else path.name


# -- parsing ---------------------------------------------------------------------------------------

FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")
ANNOTATION = re.compile(r"^\s*<!--\s*test:(?P<body>.*?)-->\s*$")


@dataclass
class Block:
    path: Path
    line: int  # 1-based line of the opening fence
    info: str
    code: str
    annotations: list[str] = field(default_factory=list)  # the directives' text, one per comment line

    @property
    def id(self) -> str:
        return f"{rel(self.path)}:L{self.line}"

    @property
    def kind(self) -> str | None:
        return RUNNABLE.get(self.info.split()[0].lower()) if self.info else None


def parse_blocks(path: Path) -> list[Block]:
    """Every fenced code block of a Markdown file, with the test annotations right above it."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, start = m["fence"], i
        notes = []
        j = i - 1
        while j >= 0 and (a := ANNOTATION.match(lines[j])):
            notes.insert(0, a["body"].strip())
            j -= 1
        body = []
        i += 1
        while i < len(lines) and not re.match(rf"^ {{0,3}}{re.escape(fence[0])}{{{len(fence)},}}\s*$", lines[i]):
            body.append(lines[i][len(m["indent"]):] if lines[i].startswith(m["indent"]) else lines[i])
            i += 1
        blocks.append(Block(path, start + 1, m["info"].strip(), "\n".join(body) + "\n", notes))
        i += 1
    return blocks


@dataclass
class Plan:
    """What the annotations ask for."""

    skip: str | None = None
    replacements: list[tuple[str, str]] = field(default_factory=list)
    needs_scenes: bool = False


def plan_of(block: Block) -> Plan:
    plan = Plan()
    for note in block.annotations:
        if note.split(maxsplit=1)[:1] == ["skip"]:
            reason = note[len("skip"):].strip()
            if not reason:
                raise ValueError(f"{block.id}: `skip` needs a reason")
            plan.skip = reason
            continue
        lex = shlex.shlex(note, posix=True, punctuation_chars=";")
        lex.whitespace_split = True
        words = list(lex)
        directives: list[list[str]] = [[]]
        for w in words:
            if w == ";":
                directives.append([])
            else:
                directives[-1].append(w)
        for d in filter(None, directives):
            if d[0] == "replace" and len(d) == 3:
                plan.replacements.append((d[1], d[2]))
            elif d == ["needs-scenes"]:
                plan.needs_scenes = True
            elif d[0] == "example-paths":
                continue  # a page-level directive (see example_paths)
            else:
                raise ValueError(f"{block.id}: unknown test directive {' '.join(d)!r} "
                                 "(replace \"OLD\" \"NEW\"; skip REASON; needs-scenes; example-paths PATH...)")
    return plan


def needs_shared_scenes() -> re.Pattern[str]:
    """Words that make a block depend on the shared scene folder: its path, its variable, and the
    built-in scenes whose JSON reads files from it."""
    names = [p.stem for p in builtin_dir().glob("*.json") if "${PYCLPT_SCENES}" in p.read_text()]
    words = ["shared/scenes", "PYCLPT_SCENES", *names]
    return re.compile("|".join(rf"(?<![\w-]){re.escape(w)}(?![\w-])" for w in words))


def runnable_code(block: Block, plan: Plan) -> str:
    """The block's code with the annotations' replacements (console blocks: their ``$`` lines)."""
    code = block.code
    for old, new in plan.replacements:
        if old not in code:
            raise AssertionError(f"{block.id}: the annotation replaces {old!r}, which the block does not contain")
        if "\n" in new:
            raise AssertionError(f"{block.id}: a replacement may not add lines ({new!r})")
        code = code.replace(old, new)
    if block.kind == "console":
        commands = [ln[2:] for ln in code.splitlines() if ln.startswith("$ ")]
        if not commands:
            raise AssertionError(f"{block.id}: a console block without `$ ` command lines: use ```text")
        code = "\n".join(commands) + "\n"
    return code


ALL_BLOCKS = [b for p in doc_files() for b in parse_blocks(p)]
RUN_BLOCKS = [b for b in ALL_BLOCKS if b.kind]


# -- running ---------------------------------------------------------------------------------------

DRIVER = r"""
import json, os, sys, traceback
reply = os.fdopen(os.dup(1), "w")      # the test's channel; the examples' stdout goes to the log
os.dup2(2, 1)
sys.stdout = os.fdopen(1, "w", buffering=1)
namespace = {"__name__": "__main__"}
for line in sys.stdin:
    request = json.loads(line)
    try:
        exec(compile(request["code"], request["file"], "exec"), namespace)
        result = {"ok": True}
    except BaseException:
        result = {"ok": False, "error": traceback.format_exc()}
    sys.stdout.flush()
    sys.stderr.flush()
    reply.write(json.dumps(result) + "\n")
    reply.flush()
"""


class PageSession:
    """The blocks of one Markdown file: one working folder, one Python interpreter, run in order."""

    def __init__(self, path: Path, workdir: Path, env: dict[str, str]) -> None:
        self.path, self.workdir, self.env = path, workdir, env
        self.blocks = [b for b in RUN_BLOCKS if b.path == path]
        self.done: dict[int, str | None] = {}  # block line -> None (passed or skipped) or the failure
        self.log = workdir.parent / f"{workdir.name}.python.log"
        self.proc: subprocess.Popen | None = None

    # The test for block k first runs the page's earlier blocks that have not run (e.g. with -k).
    def run(self, block: Block) -> None:
        earlier = []
        for b in self.blocks:
            if b.line == block.line:
                break
            if b.line not in self.done:
                self.done[b.line] = self._run_one(b, quiet=True)
            if self.done[b.line]:
                earlier.append(f"{b.id}")
        error = self._run_one(block, quiet=False)
        self.done[block.line] = error
        if error:
            note = f"\n(earlier blocks of this page failed: {', '.join(earlier)})" if earlier else ""
            pytest.fail(error + note, pytrace=False)

    def _run_one(self, block: Block, quiet: bool) -> str | None:
        plan = plan_of(block)
        if plan.skip:
            if quiet:
                return None
            pytest.skip(f"annotated: {plan.skip}")
        if (plan.needs_scenes or NEEDS_SCENES.search(block.code)) and shared_scenes() is None:
            if quiet:
                return None
            pytest.skip("needs the shared scene folder (PYCLPT_SCENES, ../shared/scenes), not found")
        code = runnable_code(block, plan)
        if block.kind == "python":
            return self._python(block, code)
        return self._shell(block, code)

    def _shell(self, block: Block, code: str) -> str | None:
        try:
            out = subprocess.run(["bash", "-euo", "pipefail", "-c", code], cwd=self.workdir, env=self.env,
                                 stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 text=True, timeout=BLOCK_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            return f"{block.id}: still running after {BLOCK_TIMEOUT_S} s:\n{code}"
        if out.returncode != 0:
            return (f"{block.id}: exit status {out.returncode}\n--- block as run:\n{code}"
                    f"--- output:\n{out.stdout[-6000:]}")
        return None

    def _python(self, block: Block, code: str) -> str | None:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen([sys.executable, "-c", DRIVER], cwd=self.workdir, env=self.env,
                                         stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                         stderr=self.log.open("ab"), text=True)
        start = self.log.stat().st_size
        # leading newlines keep the Markdown file's line numbers in tracebacks
        request = {"code": "\n" * block.line + code, "file": str(block.path)}
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        ready, _, _ = select.select([self.proc.stdout], [], [], BLOCK_TIMEOUT_S)
        line = self.proc.stdout.readline() if ready else ""
        output = self.log.read_bytes()[start:].decode(errors="replace")[-6000:]
        if not ready:
            self.close()
            return f"{block.id}: still running after {BLOCK_TIMEOUT_S} s\n--- output:\n{output}"
        if not line:
            code = self.proc.wait()
            self.proc = None
            return f"{block.id}: the interpreter exited (status {code})\n--- output:\n{output}"
        result = json.loads(line)
        if not result["ok"]:
            return f"{block.id}: {result['error']}--- output:\n{output}"
        return None

    def close(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None


NEEDS_SCENES = needs_shared_scenes()


def block_env(shims: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(shims), str(Path(sys.executable).parent), env.get("PATH", "")])
    if env.get("PYTHONPATH"):  # the working folder changes: relative entries would break
        env["PYTHONPATH"] = os.pathsep.join(os.path.abspath(p) for p in env["PYTHONPATH"].split(os.pathsep) if p)
    root = shared_scenes()
    if root is not None:
        env["PYCLPT_SCENES"] = str(root)
    else:
        env.pop("PYCLPT_SCENES", None)
    env[GUARD] = "1"
    env.setdefault("MPLBACKEND", "Agg")
    return env


def make_shims(folder: Path) -> Path:
    """``python``/``python3`` as this interpreter; ``pyclpt`` as its console script, or the module."""
    folder.mkdir(parents=True, exist_ok=True)
    script = Path(sys.executable).parent / "pyclpt"
    # scripts, not links: a virtual environment's python finds its site-packages from its own path
    commands = {"python": f'"{sys.executable}"', "python3": f'"{sys.executable}"',
                "pyclpt": f'"{script}"' if script.is_file() else f'"{sys.executable}" -m pyclpt.cli'}
    for name, command in commands.items():
        (folder / name).write_text(f'#!/bin/sh\nexec {command} "$@"\n')
        (folder / name).chmod(0o755)
    return folder


@pytest.fixture(scope="module")
def sessions(tmp_path_factory) -> Iterator[dict[Path, PageSession]]:
    base = tmp_path_factory.mktemp("docs")
    root = shared_scenes()
    if root is not None:
        (base / "shared").mkdir()
        (base / "shared" / "scenes").symlink_to(root, target_is_directory=True)
    env = block_env(make_shims(base / "bin"))
    out: dict[Path, PageSession] = {}
    for path in doc_files():
        work = base / re.sub(r"[^\w.-]", "_", rel(path))
        work.mkdir()
        if (REPO / "bench").is_dir():
            (work / "bench").symlink_to(REPO / "bench", target_is_directory=True)
        out[path] = PageSession(path, work, env)
    yield out
    for s in out.values():
        s.close()


@pytest.mark.parametrize("block", RUN_BLOCKS, ids=[b.id for b in RUN_BLOCKS])
def test_doc_block(block: Block, sessions: dict[Path, PageSession]) -> None:
    sessions[block.path].run(block)


# -- blocks that do not run ------------------------------------------------------------------------

COMMAND_LIKE = re.compile(r"^(\$ |pyclpt |python3? |pip |pytest|import |from \w+ import )")


def test_every_block_says_what_it_is() -> None:
    """A block without an info string, or one that looks like a command but would not run, hides
    an example from the tests; the annotations must parse and their replacements must apply."""
    problems = []
    for b in ALL_BLOCKS:
        if not b.info:
            problems.append(f"{b.id}: no info string (```sh, ```python, or ```text for output)")
        elif not b.kind and COMMAND_LIKE.match(b.code.lstrip()):
            problems.append(f"{b.id}: looks like a command but is ```{b.info}, so no test runs it")
        elif b.annotations and not b.kind:
            problems.append(f"{b.id}: a test annotation on a ```{b.info} block, which never runs")
        elif b.kind:
            try:
                runnable_code(b, plan_of(b))
            except (ValueError, AssertionError) as exc:
                problems.append(str(exc))
    assert not problems, "\n".join(problems)


def test_the_parser_finds_blocks_and_annotations(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text('<!-- test: example-paths cl/new.h pyclpt/new.py -->\n'
                    '\n<!-- test: replace "--spp 64" "--spp 2"; needs-scenes -->\n```sh\n'
                    'pyclpt render x --spp 64\n```\n\n````text\n```python\nnot a block\n```\n````\n'
                    "<!-- test: skip it's slow; very -->\n```python\nprint(1)\n```\n")
    blocks = parse_blocks(page)
    assert [(b.line, b.info) for b in blocks] == [(4, "sh"), (8, "text"), (14, "python")]
    assert example_paths(page) == {"cl/new.h", "pyclpt/new.py"}
    first, _, last = (plan_of(b) for b in blocks)
    assert first.replacements == [("--spp 64", "--spp 2")] and first.needs_scenes and not first.skip
    assert runnable_code(blocks[0], first) == "pyclpt render x --spp 2\n"
    assert last.skip == "it's slow; very"
    with pytest.raises(AssertionError, match="does not contain"):
        runnable_code(blocks[2], Plan(replacements=[("absent", "x")]))


# -- names, paths and links the docs mention -------------------------------------------------------

INLINE_CODE = re.compile(r"(?<!`)(`+)(?!`)(.+?)(?<!`)\1(?!`)", re.S)
DOTTED = re.compile(r"(?<![\w./-])pyclpt(?:\.[A-Za-z_]\w*)+")
# the names of `from pyclpt... import a, b` (one line) or `import (a,\n b)` (parenthesised, several lines)
FROM_IMPORT = re.compile(r"^[ \t]*from (pyclpt(?:\.\w+)*) import (?:\(([\w\s,]+)\)|([\w \t,]+))", re.M)
ATTRIBUTE = re.compile(r"^([A-Z]\w*)\.([a-z_]\w*)")


def _prose(text: str) -> str:
    """The text outside fenced blocks."""
    out, inside = [], None
    for line in text.splitlines():
        m = FENCE.match(line)
        if m and inside is None:
            inside = m["fence"]
        elif inside is not None and line.strip().startswith(inside):
            inside = None
        elif inside is None:
            out.append(line)
    return "\n".join(out)


def inline_code(path: Path) -> list[str]:
    return [m[2].strip() for m in INLINE_CODE.finditer(_prose(path.read_text(encoding="utf-8")))]


def documented_names() -> dict[str, set[str]]:
    """``pyclpt.X.Y`` references (code blocks of any language, inline code) -> the files naming them."""
    names: dict[str, set[str]] = {}
    for path in doc_files():
        texts = inline_code(path) + [b.code for b in parse_blocks(path) if b.kind in ("python", "shell", "console")]
        for text in texts:
            found = DOTTED.findall(text)
            for module, wrapped, items in FROM_IMPORT.findall(text):
                found += [f"{module}.{n.strip()}" for n in (wrapped or items).split(",") if n.strip()]
            for name in found:
                names.setdefault(name, set()).add(rel(path))
    return names


DOCUMENTED = documented_names()


def resolve(dotted: str) -> object:
    """Import the longest module prefix of ``dotted``, then get the remaining attributes."""
    parts = dotted.split(".")
    for n in range(len(parts), 0, -1):
        module_name = ".".join(parts[:n])
        try:
            obj: object = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name is not None and module_name.startswith(exc.name) and exc.name != "pyclpt":
                continue
            raise
        for attr in parts[n:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(dotted)


@pytest.mark.parametrize("name", sorted(DOCUMENTED))
def test_documented_name_imports_from_pyclpt(name: str) -> None:
    where = ", ".join(sorted(DOCUMENTED[name]))
    top = name.split(".")[1]
    is_module = importlib.util.find_spec(f"pyclpt.{top}") is not None
    if not is_module:
        assert top in pyclpt.__all__ or (top.startswith("__") and top.endswith("__")), \
            f"{name} ({where}): pyclpt.{top} is not in pyclpt.__all__, the public API"
    try:
        resolve(name)
    except (ImportError, AttributeError) as exc:
        pytest.fail(f"{name} ({where}) does not resolve: {exc}", pytrace=False)


def test_documented_class_attributes_exist() -> None:
    """Inline ``Renderer.render``, ``Accumulator.image(...)``, ``RenderStats.setup_seconds``: the
    attribute (or dataclass field) exists on the public class."""
    missing = []
    for path in doc_files():
        for text in inline_code(path):
            m = ATTRIBUTE.match(text)
            if not m or m[1] not in pyclpt.__all__:
                continue
            cls = getattr(pyclpt, m[1])
            fields = {f.name for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else set()
            if not hasattr(cls, m[2]) and m[2] not in fields:
                missing.append(f"{rel(path)}: `{text}`: {m[1]} has no attribute {m[2]!r}")
    assert not missing, "\n".join(missing)


BARE_CLASS = re.compile(r"^([A-Z][a-z]\w*)(?=$|[.(\[])")
# Names of other projects that the docs mention in inline code.
FOREIGN_NAMES = {"ForAllQueued", "ScalarTransform4f", "LocalCluster", "Client"}  # pbrt-v4; Mitsuba 3; Dask


def test_documented_classes_exist() -> None:
    """A class named in inline code (`SceneBuffers`, `RenderStats.setup_seconds`) is public API, a
    class or name defined in pyclpt's or bench's sources, a type of the OpenCL sources, a Python
    builtin, or another project's."""
    sources = "\n".join(p.read_text() for folder in ("pyclpt", "bench") for p in (REPO / folder).rglob("*.py"))
    cl_sources = "\n".join(p.read_text() for p in (REPO / "cl").rglob("*") if p.suffix in (".h", ".cl"))
    missing = []
    for path in doc_files():
        for text in inline_code(path):
            m = BARE_CLASS.match(text)
            if not m:
                continue
            name = m[1]
            if name in pyclpt.__all__ or name in FOREIGN_NAMES or hasattr(builtins, name):
                continue
            if not (re.search(rf"^\s*(?:class {name}\b|{name}\s*[:=])", sources, re.M)
                    or re.search(rf"(?:}}\s*{name}\s*;|struct {name}\b)", cl_sources)):
                missing.append(f"{rel(path)}: `{text}`: {name} is defined nowhere in pyclpt or bench")
    assert not missing, "\n".join(missing)


def example_paths(path: Path) -> set[str]:
    """Paths a page names as files to create (``<!-- test: example-paths PATH ... -->`` anywhere in it)."""
    out: set[str] = set()
    for line in path.read_text(encoding="utf-8").splitlines():
        if (a := ANNOTATION.match(line)) and a["body"].split()[:1] == ["example-paths"]:
            out.update(a["body"].split()[1:])
    return out


REPO_PATH = re.compile(r"^(?:pyclpt|cl|bench|tests|scenes|docs|\.ci)/[\w./*-]*(?:::\w+)?$")


def test_documented_paths_exist() -> None:
    """Inline code naming a file of the repository (``cl/film/accumulate.h``, ``tests/test_x.py::test_y``)."""
    missing = []
    for path in doc_files():
        examples = example_paths(path)
        for text in inline_code(path):
            for word in text.split():
                if not REPO_PATH.match(word) or word in examples:
                    continue
                file, _, test = word.partition("::")
                matches = list(REPO.glob(file.rstrip("/"))) if "*" in file else [REPO / file]
                if not any(p.exists() for p in matches):
                    missing.append(f"{rel(path)}: `{word}` does not exist")
                elif test and not re.search(rf"^\s*(?:async )?def {test}\(", matches[0].read_text(), re.M):
                    missing.append(f"{rel(path)}: `{word}`: no test {test} in {file}")
    assert not missing, "\n".join(missing)


LINK = re.compile(r"\[[^\]]*\]\((?P<target>[^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    return {slug(line.lstrip("#")) for line in _prose(path.read_text(encoding="utf-8")).splitlines()
            if re.match(r"^#{1,6} ", line)}


def test_relative_links_resolve() -> None:
    broken = []
    for path in doc_files():
        for m in LINK.finditer(_prose(path.read_text(encoding="utf-8"))):
            target = m["target"]
            if re.match(r"^[a-z]+:", target):
                continue
            file, _, anchor = target.partition("#")
            dest = (path.parent / file).resolve() if file else path
            if not dest.exists():
                broken.append(f"{rel(path)}: link to {target}: no such file")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                broken.append(f"{rel(path)}: link to {target}: no heading #{anchor} in {dest.name}")
    assert not broken, "\n".join(broken)


def test_docs_exist_and_readme_links_getting_started() -> None:
    assert RUN_BLOCKS, "no runnable documentation blocks found"
    assert (REPO / "docs" / "getting-started.md").is_file()
    assert "docs/getting-started.md" in (REPO / "README.md").read_text()
    assert shutil.which("bash"), "the documentation tests need bash"
