"""The README's and the docs pages' commands run as written and print what they say they print.

README.md and every ``docs/*.md`` page mark what this test runs with an HTML comment on the line
before a code block (the same rules on every page; a page's quotes refer to its own blocks):

- ``<!-- test: runs -->`` before a ```` ```bash ```` block: the block runs in bash (``-e``: every
  command must exit 0); before a ```` ```python ```` block, in this Python, in a fresh directory holding the repository's ``examples/``, ``scripts/``
  and ``robots/``, with ``tcr-accuracy``, ``python`` and ``python3`` on the PATH running this
  checkout.
- ``<!-- test: prints -->`` before a plain ```` ``` ```` block: its lines are printed, in this
  order and next to each other, by the nearest ``runs`` block above it (a line ending in
  ``...`` matches any line that starts with what comes before the dots).
- ``<!-- test: output of COMMAND -->`` before a plain block: the same for ``COMMAND`` run on
  its own.
- ``<!-- test: console -->`` before a ```` ```console ```` block: each ``$ command`` prints
  exactly the lines below it.

The figures quoted in a page are what the code printed when the page was written; the test reads
them from the page, never from the code under test. Long benchmarks
(``scripts/*_benchmark.py``) are not marked and not run. The blocks run two at a time.
"""

from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
#: Every page whose marked blocks run: the README and each docs page.
PAGES = [README, *sorted((REPO / "docs").glob("*.md"))]
MARKER = re.compile(r"^<!-- test: (?P<kind>runs|prints|console|output of (?P<command>.+?)) -->$")
FENCE = re.compile(r"^```(?P<lang>\w*)$")
LINKED = ("examples", "scripts", "robots")


@dataclass
class Block:
    kind: str            # runs | prints | console | output
    line: int            # the page's line of the marker (1-based)
    text: str            # the code block's contents
    command: str = ""    # for kind 'output'
    source: int = 0      # for kind 'prints': the page's line of the runs block it quotes
    lang: str = ""
    page: Path = README  # the page the block is on

    @property
    def where(self) -> str:
        """``README.md:12``, ``docs/diagnosis.md:40``: the block's place, as an error names it."""
        return f"{_page_name(self.page)}:{self.line}"

    @property
    def key(self) -> tuple[str, int]:
        """The block's page and line: what its run is stored under."""
        return (_page_name(self.page), self.line)

    @property
    def source_key(self) -> tuple[str, int]:
        """The key of the run whose output this block quotes (its own for 'output')."""
        return (_page_name(self.page), self.source or self.line)


def _page_name(page: Path) -> str:
    try:
        return page.relative_to(REPO).as_posix()
    except ValueError:
        return page.name


def readme_blocks(path: Path = README) -> list[Block]:
    """Every marked code block of a page (the README by default), in order."""
    lines = path.read_text(encoding="utf-8").splitlines()
    name = _page_name(path)
    blocks: list[Block] = []
    last_runs = 0
    i = 0
    while i < len(lines):
        marker = MARKER.match(lines[i].strip())
        if marker is None:
            i += 1
            continue
        fence = FENCE.match(lines[i + 1]) if i + 1 < len(lines) else None
        assert fence is not None, f"{name}:{i + 1}: a test marker must sit right above a ``` line"
        end = next((k for k in range(i + 2, len(lines)) if lines[k] == "```"), None)
        assert end is not None, f"{name}:{i + 1}: code block without its closing ```"
        kind = marker["kind"]
        block = Block("output" if marker["command"] else kind, i + 1, "\n".join(lines[i + 2:end]),
                      command=marker["command"] or "", lang=fence["lang"], page=path)
        if kind == "runs":
            assert block.lang in ("bash", "sh", "python"), f"{name}:{i + 1}: 'runs' marks a bash or python block"
            last_runs = block.line
        elif kind == "prints":
            assert last_runs, f"{name}:{i + 1}: 'prints' with no 'runs' block above it"
            block.source = last_runs
        blocks.append(block)
        i = end + 1
    return blocks


@dataclass
class Run:
    returncode: int
    stdout: str
    stderr: str
    outputs: dict = field(default_factory=dict)  # for console blocks: command -> stdout


def _workdir(tmp: Path) -> tuple[Path, dict]:
    """A fresh directory with the repository's example inputs and a PATH running this checkout."""
    tmp.mkdir(parents=True)
    for name in LINKED:
        (tmp / name).symlink_to(REPO / name, target_is_directory=True)
    bin_dir = tmp / ".bin"
    bin_dir.mkdir()
    shims = {"tcr-accuracy": f'exec "{sys.executable}" -m tcr_accuracy "$@"',
             "python": f'exec "{sys.executable}" "$@"', "python3": f'exec "{sys.executable}" "$@"'}
    for name, body in shims.items():
        shim = bin_dir / name
        shim.write_text(f"#!/bin/sh\n{body}\n")
        shim.chmod(shim.stat().st_mode | stat.S_IXUSR)
    pythonpath = os.pathsep.join(p for p in (str(REPO / "src"), os.environ.get("PYTHONPATH", "")) if p)
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "PYTHONPATH": pythonpath,
           "MPLBACKEND": "Agg", "COLUMNS": "200"}
    return tmp, env


def _bash(script: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-e", "-c", script], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)


def _execute(block: Block, tmp: Path) -> Run:
    cwd, env = _workdir(tmp)
    if block.kind == "runs" and block.lang == "python":
        (cwd / "snippet.py").write_text(block.text + "\n")
        done = subprocess.run([sys.executable, "snippet.py"], cwd=cwd, env=env, capture_output=True, text=True,
                              timeout=600)
        return Run(done.returncode, done.stdout, done.stderr)
    if block.kind == "runs":
        done = _bash(block.text, cwd, env)
        return Run(done.returncode, done.stdout, done.stderr)
    if block.kind == "output":
        done = _bash(block.command, cwd, env)
        return Run(done.returncode, done.stdout, done.stderr)
    # console: '$ command' lines, each followed by its expected output
    run = Run(0, "", "")
    for command in (line[2:] for line in block.text.splitlines() if line.startswith("$ ")):
        done = _bash(command, cwd, env)
        run.outputs[command] = done.stdout
        run.stderr += done.stderr
        run.returncode = run.returncode or done.returncode
    return run


def all_blocks() -> list[Block]:
    """Every marked block of every page (README first, then docs/ in name order)."""
    return [b for page in PAGES for b in readme_blocks(page)]


BLOCKS = all_blocks()
EXECUTED = [b for b in BLOCKS if b.kind in ("runs", "output", "console")]


def run_blocks(blocks: list[Block], base: Path, workers: int = 2) -> dict:
    """Run every executed block, ``workers`` at a time, each in its own fresh folder under ``base``;
    the runs by the block's key, the longest-running pages' blocks started first."""
    executed = sorted((b for b in blocks if b.kind in ("runs", "output", "console")),
                      key=lambda b: b.page == README)   # the docs' long blocks (seed reproduction) first
    with ThreadPoolExecutor(max_workers=workers) as pool:
        futures = {b.key: pool.submit(_execute, b, base / f"{b.page.stem}-line{b.line}") for b in executed}
        return {key: future.result() for key, future in futures.items()}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict:
    """Every executed block of every page, by (page, line of its marker): two at a time in one pool."""
    return run_blocks(BLOCKS, tmp_path_factory.mktemp("readme"))


def _contains_in_order(expected: list[str], printed: list[str]) -> bool:
    """True when the expected lines appear next to each other in the printed ones."""
    def same(want: str, got: str) -> bool:
        if want.endswith("..."):
            return got.startswith(want[:-3].rstrip())
        return want == got

    for start in range(len(printed) - len(expected) + 1):
        if all(same(w, g) for w, g in zip(expected, printed[start:start + len(expected)])):
            return True
    return False


def _lines(text: str) -> list[str]:
    return [line.rstrip() for line in text.splitlines()]


def _ids(block: Block) -> str:
    return f"{block.page.stem}-line{block.line}"


def test_readme_has_marked_blocks():
    kinds = [b.kind for b in BLOCKS if b.page == README]
    # the Quickstart's demo summary and one command block per task at least
    assert kinds.count("runs") >= 4 and "prints" in kinds and "output" in kinds


def test_docs_have_their_commands_marked():
    """Every docs page that shows a command's output has it checked (a quote moved out of the README
    stays checked): the pages with marked blocks, and every kind of block somewhere in docs/."""
    docs = [b for b in BLOCKS if b.page != README]
    pages = {b.page.name for b in docs}
    assert {"seed-reproduction.md", "programs.md"} <= pages
    assert {"runs", "prints", "console"} <= {b.kind for b in docs}


@pytest.mark.slow
@pytest.mark.parametrize("block", EXECUTED, ids=_ids)
def test_block_runs(block, runs):
    run = runs[block.key]
    assert run.returncode == 0, f"{block.where}: the block exits {run.returncode}:\n{run.stderr[-3000:]}"


@pytest.mark.slow
@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind in ("prints", "output")], ids=_ids)
def test_quoted_output_is_printed(block, runs):
    run = runs[block.source_key]
    expected = _lines(block.text)
    assert _contains_in_order(expected, _lines(run.stdout)), (
        f"{block.where}: these lines are not what the commands print now:\n{block.text}\n"
        f"--- printed ---\n{run.stdout[-6000:]}")


@pytest.mark.slow
@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind == "console"], ids=_ids)
def test_console_session_prints_exactly(block, runs):
    run = runs[block.key]
    expected: dict[str, list[str]] = {}
    command = None
    for line in block.text.splitlines():
        if line.startswith("$ "):
            command = line[2:]
            expected[command] = []
        elif command is not None:
            expected[command].append(line.rstrip())
    for command, lines in expected.items():
        assert _lines(run.outputs[command]) == lines, f"{block.where}: `{command}` prints\n{run.outputs[command]}"


def test_matcher_rejects_what_is_not_there():
    printed = ["a 1.00", "b 2.00", "c 3.00"]
    assert _contains_in_order(["b 2.00", "c 3.00"], printed)
    assert _contains_in_order(["b 2...", "c 3.00"], printed)
    assert not _contains_in_order(["c 3.00", "b 2.00"], printed)      # order
    assert not _contains_in_order(["a 1.00", "c 3.00"], printed)      # next to each other
    assert not _contains_in_order(["b 2.01"], printed)                # a figure off by one digit


def test_marker_parser_ties_prints_to_the_runs_block_above(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("text\n<!-- test: runs -->\n```bash\necho hi\n```\nprose\n<!-- test: prints -->\n```\nhi\n```\n"
                      "<!-- test: output of echo x -->\n```\nx\n```\n")
    blocks = readme_blocks(readme)
    assert [(b.kind, b.line, b.source, b.command) for b in blocks] == [
        ("runs", 2, 0, ""), ("prints", 7, 2, ""), ("output", 11, 0, "echo x")]


def test_a_page_quotes_its_own_blocks(tmp_path):
    """Two pages with a runs block on the same line: each page's quote is tied to its own run."""
    first, second = tmp_path / "a.md", tmp_path / "b.md"
    for page, word in ((first, "one"), (second, "two")):
        page.write_text(f"<!-- test: runs -->\n```bash\necho {word}\n```\n<!-- test: prints -->\n```\n{word}\n```\n")
    blocks = readme_blocks(first) + readme_blocks(second)
    runs = run_blocks(blocks, tmp_path / "runs")
    assert set(runs) == {("a.md", 1), ("b.md", 1)}
    for quote in (b for b in blocks if b.kind == "prints"):
        assert _contains_in_order(_lines(quote.text), _lines(runs[quote.source_key].stdout))
    assert not _contains_in_order(["two"], _lines(runs[("a.md", 1)].stdout))


def test_scripts_with_a_shebang_can_be_run_directly():
    """`scripts/blind_benchmark.py --scenarios 40` as the README writes it needs the run bit (in git too)."""
    scripts = sorted(p for p in (REPO / "scripts").iterdir() if p.is_file())
    with_shebang = [p for p in scripts if p.read_bytes().startswith(b"#!")]
    assert {p.name for p in with_shebang} >= {"blind_benchmark.py", "seed2_benchmark.py", "test.sh"}
    not_executable = [p.name for p in with_shebang if not os.access(p, os.X_OK)]
    assert not not_executable, f"no run bit: {not_executable}"
    listed = subprocess.run(["git", "ls-files", "-s", "scripts"], cwd=REPO, capture_output=True, text=True,
                            timeout=60)
    if listed.returncode == 0 and listed.stdout:  # in a git checkout: the mode git stores is what a clone gets
        modes = {Path(line.split("\t")[1]).name: line.split()[0] for line in listed.stdout.splitlines()}
        wrong = [p.name for p in with_shebang if modes.get(p.name, "100755") != "100755"]
        assert not wrong, f"git stores these without the run bit (git update-index --chmod=+x): {wrong}"


def test_python_scripts_start_with_a_shebang():
    missing = [p.name for p in (REPO / "scripts").glob("*.py") if not p.read_bytes().startswith(b"#!")]
    assert not missing, f"scripts without '#!/usr/bin/env python3': {missing}"
