"""Examples are tests: every ``grasplan ...`` line of a fenced ``sh`` block in README.md and docs/*.md
runs, and exits as the text says.

A block's lines run in order in one temporary folder that sees the repository's ``examples/``,
``configs/`` and ``robots/`` (symbolic links), so a block may make files with earlier lines and use
them in later ones (``out/plan.json``). A line expects exit 0 unless its comment says otherwise:
``grasplan ... # exit 4``. A line with a placeholder (``PART``, ``OUT.json``, ``[--top K]``) is a
synopsis, not an example. Lines naming the paper parts (``../shared/parts/paper``) run only when that
folder exists. An example whose input files are missing fails.

By default a cheap subset runs: the README's blocks, for every command the block of its first
example, and the blocks using the shipped scene (``examples/scenes/``), leaving out costly ones (``batch``, ``clutter``, ``serve``). Every block
runs with ``GRASPLAN_DOC_EXAMPLES=all``; ``grasplan serve`` then starts in the background and the
test asks its ``/health`` and posts the shipped pile (``examples/scenes/pile.json``) to ``/pick``
as docs/serve.md shows."""
from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT.parent / "shared" / "parts" / "paper"
ALL = os.environ.get("GRASPLAN_DOC_EXAMPLES", "") == "all"
LINKED = ("examples", "configs", "robots")

#: commands that cost tens of seconds or more (or run a service): run only with GRASPLAN_DOC_EXAMPLES=all
COSTLY = {"batch", "clutter", "serve"}
#: (page, start of the line) -> why it cannot run on one machine; each must still match a line
NOT_RUN = {
    ("docs/batch.md", "grasplan batch catalogue/ -o out/ --engine ray --ray-address 10.0.0.5"):
        "needs a Ray cluster at 10.0.0.5",
}
PLACEHOLDER = re.compile(r"^\[|^[A-Z][A-Z_]+(?:\.\.\.|\.\w+)?$")


@dataclass(frozen=True)
class Line:
    page: str
    lineno: int
    text: str          #: the command, continuations joined, comment removed
    comment: str
    expect: int        #: exit code the text states

    @property
    def argv(self) -> list[str]:
        return shlex.split(self.text)

    @property
    def command(self) -> str:
        """``plan``, ``scene drop``, ..."""
        args = self.argv[1:]
        return " ".join(args[:2]) if args[:1] == ["scene"] else (args[0] if args else "")

    @property
    def synopsis(self) -> bool:
        return any(PLACEHOLDER.match(a) for a in self.argv[1:])


@dataclass(frozen=True)
class Block:
    page: str
    lineno: int
    lines: tuple[Line, ...]

    @property
    def name(self) -> str:
        return f"{self.page}:{self.lineno}"


def _split_comment(line: str) -> tuple[str, str]:
    """A shell line without its trailing ``# comment`` (a ``#`` outside quotes after a blank)."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip(), line[i + 1:].strip()
    return line.rstrip(), ""


def blocks(root: Path = ROOT) -> list[Block]:
    out = []
    for path in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
        page = str(path.relative_to(root))
        text = path.read_text()
        for m in re.finditer(r"^```sh\n(.*?)^```", text, flags=re.M | re.S):
            first = text[:m.start()].count("\n") + 2
            lines, pending, start = [], "", 0
            for k, raw in enumerate(m.group(1).splitlines()):
                code, comment = _split_comment(raw)
                if not pending:
                    start, comments = first + k, []
                comments.append(comment)
                if code.endswith("\\"):
                    pending += code[:-1] + " "
                    continue
                code, pending = (pending + code).strip(), ""
                words = code.split()
                if words and words[0] in ("grasplan", ".venv/bin/grasplan"):
                    note = " ".join(c for c in comments if c)
                    exit_ = re.search(r"\bexit (\d+)\b", note)
                    lines.append(Line(page, start, code, note, int(exit_.group(1)) if exit_ else 0))
            if lines:
                out.append(Block(page, first - 1, tuple(lines)))
    return out


def _not_run(line: Line) -> str | None:
    for (page, start), why in NOT_RUN.items():
        if line.page == page and line.text.startswith(start):
            return why
    return None


def _costly(block: Block) -> bool:
    return any(ln.command in COSTLY for ln in block.lines)


def default_blocks(every: list[Block]) -> set[str]:
    """The README's blocks, each command's first example's block and the blocks using the shipped
    scene, without the costly ones."""
    chosen, seen = set(), set()
    for b in every:
        runnable = [ln for ln in b.lines if not ln.synopsis and not _not_run(ln)]
        new = {ln.command for ln in runnable} - seen
        seen |= new
        shipped = any("examples/scenes/" in ln.text for ln in runnable)
        if runnable and (b.page == "README.md" or new or shipped) and not _costly(b):
            chosen.add(b.name)
    return chosen


BLOCKS = blocks()
DEFAULT = default_blocks(BLOCKS)


def _rewrite(arg: str) -> str:
    return arg.replace("../shared/parts/paper", str(PAPER))


class Runner:
    """Runs lines in process (kernels compile once for the whole file); remembers each block's
    folder after each prefix of lines so an identical prefix elsewhere is not run twice."""

    def __init__(self, base: Path):
        self.base = base
        self.done: dict[tuple[tuple[str, int], ...], Path] = {}
        self.count = 0

    def folder(self) -> Path:
        self.count += 1
        d = self.base / f"b{self.count}"
        d.mkdir()
        for name in LINKED:
            (d / name).symlink_to(ROOT / name)
        return d

    def run_block(self, block: Block, monkeypatch) -> list[str]:
        from click.testing import CliRunner

        from grasplan.cli import main

        ran = []
        lines = [ln for ln in block.lines if not ln.synopsis and not _not_run(ln)]
        key: tuple[tuple[str, int], ...] = ()
        k = 0
        while k < len(lines) and key + ((lines[k].text, lines[k].expect),) in self.done:
            key += ((lines[k].text, lines[k].expect),)
            k += 1
        d = self.folder()
        if key:
            shutil.rmtree(d)
            shutil.copytree(self.done[key], d, symlinks=True)
        for ln in lines[k:]:
            where = f"{ln.page}:{ln.lineno}: {ln.text}"
            if "shared/parts/paper" in ln.text and not PAPER.is_dir():
                ran.append(f"skipped (no {PAPER}): {where}")
                break
            if ln.command == "serve":
                self._serve(ln, d)
            else:
                monkeypatch.chdir(d)
                result = CliRunner().invoke(main, [_rewrite(a) for a in ln.argv[1:]], catch_exceptions=True)
                if result.exception and not isinstance(result.exception, SystemExit):
                    raise AssertionError(f"{where}: raised {result.exception!r}\n{result.output}") \
                        from result.exception
                assert result.exit_code == ln.expect, (
                    f"{where}: exit {result.exit_code}, the text says {ln.expect}\n{result.output[-3000:]}")
            key += ((ln.text, ln.expect),)
            snap = self.base / f"s{len(self.done)}"
            shutil.copytree(d, snap, symlinks=True)
            self.done[key] = snap
            ran.append(where)
        return ran

    def _serve(self, ln: Line, d: Path) -> None:
        """Start the service as the page shows, ask /health, post the shipped pile to /pick."""
        exe = Path(sys.executable).with_name("grasplan")
        port = "18765"
        env = dict(os.environ, GRASPLAN_TOKEN="doc-examples")
        proc = subprocess.Popen([str(exe), *ln.argv[1:], "--port", port, "--workers", "1"], cwd=d, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            url = f"http://127.0.0.1:{port}"
            for _ in range(600):
                if proc.poll() is not None:
                    raise AssertionError(f"{ln.page}:{ln.lineno}: serve exited {proc.returncode}\n"
                                         f"{proc.stdout.read() if proc.stdout else ''}")
                try:
                    with urllib.request.urlopen(f"{url}/health", timeout=2) as r:
                        if r.status == 200:
                            break
                except OSError:
                    time.sleep(0.5)
            else:
                raise AssertionError(f"{ln.page}:{ln.lineno}: serve did not answer /health")
            scene = json.loads((ROOT / "examples" / "scenes" / "pile.json").read_text())
            body = {k: v for k, v in scene.items() if k != "parts"} | {"options": {"max_picks": 1}}
            req = urllib.request.Request(f"{url}/pick", data=json.dumps(body).encode(), method="POST",
                                         headers={"Content-Type": "application/json",
                                                  "Authorization": "Bearer doc-examples"})
            with urllib.request.urlopen(req, timeout=300) as r:
                picks = json.loads(r.read())
            assert picks["schema"] == "grasplan.picks/1"
            assert any(i["status"] == "picked" for i in picks["instances"]), picks["instances"]
        finally:
            proc.terminate()
            proc.wait(timeout=30)


def test_the_shipped_scene():
    """examples/scenes/ holds a valid grasplan.scene/1 pile of the example parts, mesh paths relative
    to the scene file and pointing at examples/parts/."""
    import hashlib

    from grasplan.schemas.documents import validate

    scenes = sorted((ROOT / "examples" / "scenes").glob("*.json"))
    assert scenes, "no scene in examples/scenes/"
    for path in scenes:
        doc = json.loads(path.read_text())
        assert doc["schema"] == "grasplan.scene/1"
        validate(doc)
        assert 2 <= len(doc["instances"]) <= 12, "a small pile: pick takes a few seconds"
        for name, spec in doc["parts"].items():
            mesh = Path(spec["mesh"])
            assert not mesh.is_absolute(), (path.name, name, mesh)
            assert (path.parent / mesh).resolve().parent == (ROOT / "examples" / "parts"), (name, mesh)
            assert (path.parent / mesh).is_file(), (name, mesh)
        assert {i["part"] for i in doc["instances"]} <= set(doc["parts"])


@pytest.fixture(scope="module")
def runner(tmp_path_factory):
    return Runner(tmp_path_factory.mktemp("doc_examples"))


def test_examples_are_found():
    """The extraction sees the walkthrough, and every NOT_RUN entry still names a line of the docs."""
    lines = [ln for b in BLOCKS for ln in b.lines]
    readme = [ln.command for ln in lines if ln.page == "README.md"]
    assert {"plan", "export", "view", "scene drop", "pick"} <= set(readme), readme
    for (page, start) in NOT_RUN:
        assert any(ln.page == page and ln.text.startswith(start) for ln in lines), (page, start)
    assert "README.md:25" in DEFAULT or any(n.startswith("README.md") for n in DEFAULT)


def test_extraction_on_a_made_up_page(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("x\n")
    (tmp_path / "docs" / "a.md").write_text(
        "```sh\nmake demo\ngrasplan plan P.stl \\\n    --top 2 -o out/p.json   # fast\n"
        "grasplan view out/p.json -o 'a # b.html'   # exit 3\n```\n"
        "```\ngrasplan not-sh\n```\n```sh\ngrasplan plan PART -o OUT.json [--top K]\n```\n")
    found = blocks(tmp_path)
    assert [b.name for b in found] == ["docs/a.md:1", "docs/a.md:10"]
    a, b = found[0].lines
    assert (a.text, a.lineno, a.expect, a.comment) == ("grasplan plan P.stl      --top 2 -o out/p.json", 3, 0, "fast")
    assert (b.argv[-1], b.expect) == ("a # b.html", 3)
    assert found[1].lines[0].synopsis and not a.synopsis


@pytest.mark.parametrize("block", BLOCKS, ids=lambda b: b.name)
def test_doc_example(block, runner, monkeypatch):
    if block.name not in DEFAULT and not ALL:
        pytest.skip("costly or not a first example: set GRASPLAN_DOC_EXAMPLES=all")
    runnable = [ln for ln in block.lines if not ln.synopsis]
    if runnable and all(_not_run(ln) for ln in runnable):
        pytest.skip("; ".join(sorted({_not_run(ln) or "" for ln in runnable})))
    if not runnable:
        pytest.skip("a synopsis, no example")
    ran = runner.run_block(block, monkeypatch)
    skipped = [r for r in ran if r.startswith("skipped")]
    if skipped:
        pytest.skip(skipped[0])


def test_a_missing_input_fails_and_an_exit_marker_is_honoured(tmp_path, monkeypatch):
    """A doc line whose input is missing fails the test (no skip); ``# exit 3`` makes it the expected
    outcome."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("```sh\ngrasplan view out/nowhere.json -o out/v.html\n```\n"
                                        "```sh\ngrasplan view out/nowhere.json -o out/v.html   # exit 3\n```\n")
    missing, marked = blocks(tmp_path)
    runner = Runner(tmp_path / "run")
    runner.base.mkdir()
    with pytest.raises(AssertionError, match="exit 3, the text says 0"):
        runner.run_block(missing, monkeypatch)
    assert runner.run_block(marked, monkeypatch) == ["README.md:5: grasplan view out/nowhere.json -o out/v.html"]
