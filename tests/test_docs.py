"""The documentation is reference, kept in shape: the README stays short, every command of
``grasplan --help`` has a page the README links, every relative link (and its #anchor) resolves, every
repository path and ``grasplan.*`` name a page gives exists, and no page reads like a lab log
(measurement history belongs in benchmarks/RESULTS.md).

Each check is a function of a folder holding ``README.md`` and ``docs/``; every test runs it on the
repository and on a copy with one violation put in, which it must report."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

ROOT = Path(__file__).resolve().parent.parent
README_MAX_LINES = 200

#: commands whose reference is a section of another command's page (the CLI's help points there)
NAMED_PAGES = {"scene": "clutter.md", "simulate": "quality.md", "fingers": "grippers.md"}

#: phrases of a lab log: issue numbers, dates and clock times, before/after figures, history
LAB_LOG = {
    "an issue number": r"\b[Ii]ssues? #?\d+",
    "the issue's": r"\b[Tt]he issue's\b",
    "a day and month": r"\b\d{1,2} (?:Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]*\b",
    "a clock time": r"\b\d{1,2}:\d{2}(?:\s*-\s*\d{1,2}:\d{2})? UTC\b",
    "an ISO date": r"\b20\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])\b",
    "'before:'": r"\b[Bb]efore:",
    "'was/were N unit'": r"\b(?:was|were) \d[\d.,]* ?(?:s|ms|us|MB|MiB|GB|%)(?![\w])",
    "a before -> after figure": r"\b\d[\d.,]* ?(?:s|ms|us|MB|MiB|GB|%)? -> \d[\d.,]* ?(?:s|ms|us|MB|MiB|GB|%)(?![\w])",
    "a load average": r"\bload average\b",
    "a history heading": r"^#+ .*\b[Hh]istory\b",
}

#: dotted ``grasplan.*`` words in the docs that are document fields, not Python names
NOT_PYTHON = {"grasplan.collision_checks"}


def pages(root: Path) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def prose(text: str) -> str:
    """The text outside fenced code blocks and inline code (links and headings live there)."""
    text = re.sub(r"^```.*?^```[^\n]*$", "", text, flags=re.M | re.S)
    return re.sub(r"`[^`\n]*`", "", text)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```[^\n]*$", "", path.read_text(), flags=re.M | re.S)
    seen: dict[str, int] = {}
    out = set()
    for m in re.finditer(r"^#+ (.+)$", text, flags=re.M):
        s = slug(m.group(1))
        n = seen.get(s, 0)
        seen[s] = n + 1
        out.add(s if n == 0 else f"{s}-{n}")
    return out


def grasplan_commands() -> list[str]:
    """The commands `grasplan --help` lists."""
    from grasplan.cli import main

    result = CliRunner().invoke(main, ["--help"])
    assert result.exit_code == 0, result.output
    section = result.output.split("Commands:", 1)[1]
    return re.findall(r"^  (\w[\w-]*)\s", section, flags=re.M)


# --- the checks -------------------------------------------------------------------------------

def readme_problems(root: Path) -> list[str]:
    n = len((root / "README.md").read_text().splitlines())
    return [] if n < README_MAX_LINES else [f"README.md has {n} lines (at most {README_MAX_LINES - 1})"]


def command_page_problems(root: Path, commands: list[str]) -> list[str]:
    readme = (root / "README.md").read_text()
    linked = set(re.findall(r"\]\(docs/([\w.-]+\.md)(?:#[\w-]+)?\)", readme))
    problems = []
    for cmd in commands:
        page = NAMED_PAGES.get(cmd, f"{cmd}.md")
        path = root / "docs" / page
        if not path.is_file():
            problems.append(f"grasplan {cmd}: no page docs/{page}")
            continue
        if f"grasplan {cmd}" not in path.read_text():
            problems.append(f"grasplan {cmd}: docs/{page} does not describe it")
        if page not in linked:
            problems.append(f"grasplan {cmd}: README.md does not link docs/{page}")
    return problems


def link_problems(root: Path) -> list[str]:
    problems = []
    for page in pages(root):
        for target in re.findall(r"\]\(([^)\s]+)\)", prose(page.read_text())):
            if re.match(r"[a-z]+:", target):  # https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            dest = (page.parent / file).resolve() if file else page
            name = page.relative_to(root)
            if not dest.exists():
                problems.append(f"{name}: link {target}: no file {file}")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                problems.append(f"{name}: link {target}: {dest.name} has no heading #{anchor}")
    return problems


def lab_log_problems(root: Path) -> list[str]:
    problems = []
    for page in pages(root):
        for no, line in enumerate(page.read_text().splitlines(), 1):
            for what, pattern in LAB_LOG.items():
                m = re.search(pattern, line)
                if m:
                    problems.append(f"{page.relative_to(root)}:{no}: {what} ({m.group(0)!r}): measurement history "
                                    "goes to benchmarks/RESULTS.md")
    return problems


def _python_name_exists(dotted: str, root: Path) -> bool:
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        base = root.joinpath(*parts[:i])
        for source in (base.with_suffix(".py"), base / "__init__.py"):
            if source.is_file():
                rest = parts[i:]
                return not rest or re.search(rf"\b{re.escape(rest[0])}\b", source.read_text()) is not None
    return False


def reference_problems(root: Path, code_root: Path = ROOT) -> list[str]:
    """Repository paths (grasplan/, tests/, benchmarks/, examples/, configs/, robots/) and
    ``grasplan.*`` names a page gives must exist in ``code_root``."""
    problems = []
    for page in pages(root):
        text = page.read_text()
        for m in re.finditer(r"(?<![\w/.-])((?:grasplan|tests|benchmarks|examples|configs|robots)/[\w/.-]*\w)(\*?)", text):
            path, glob = m.groups()
            if glob or re.search(r"/[A-Z]+(?:\.|/|$)", path):  # a pattern or a placeholder (NAME.yaml)
                continue
            if not (code_root / path).exists():
                problems.append(f"{page.relative_to(root)}: {path} does not exist")
        for m in re.finditer(r"(?<![\w.])(grasplan(?:\.\w+)+)(/\d)?", text):
            dotted, schema = m.groups()
            if schema or dotted in NOT_PYTHON:  # grasplan.plan/1 is a schema id
                continue
            if not _python_name_exists(dotted, code_root):
                problems.append(f"{page.relative_to(root)}: {dotted} names no module or name of the package")
    return problems


# --- the tests --------------------------------------------------------------------------------

@pytest.fixture()
def copy(tmp_path):
    """A copy of README.md and docs/ (and benchmarks/RESULTS.md, a link target) to put a violation in."""
    shutil.copy(ROOT / "README.md", tmp_path / "README.md")
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    (tmp_path / "benchmarks").mkdir()
    shutil.copy(ROOT / "benchmarks" / "RESULTS.md", tmp_path / "benchmarks" / "RESULTS.md")
    return tmp_path


def _append(path: Path, text: str) -> None:
    path.write_text(path.read_text() + text)


def test_readme_is_short(copy):
    assert readme_problems(ROOT) == []
    _append(copy / "README.md", "a line of lab log\n" * README_MAX_LINES)
    assert readme_problems(copy)


def test_every_command_has_a_page_the_readme_links(copy):
    commands = grasplan_commands()
    assert {"plan", "pick", "serve", "scene", "simulate"} <= set(commands), commands
    assert command_page_problems(ROOT, commands) == []
    readme = copy / "README.md"
    readme.write_text(readme.read_text().replace("](docs/pick.md)", "]"))
    (copy / "docs" / "serve.md").unlink()
    problems = command_page_problems(copy, commands)
    assert any("does not link docs/pick.md" in p for p in problems), problems
    assert any("no page docs/serve.md" in p for p in problems), problems


def test_every_relative_link_resolves(copy):
    assert link_problems(ROOT) == []
    _append(copy / "docs" / "pick.md", "\nSee [the scene format](scenes.md) and [budget](#no-such-heading).\n")
    problems = link_problems(copy)
    assert any("no file scenes.md" in p for p in problems), problems
    assert any("#no-such-heading" in p for p in problems), problems


def test_no_lab_log_in_the_docs(copy):
    assert lab_log_problems(ROOT) == []
    for line in ("Measured on 3 December at 16:30 UTC (issue 20): 9.65 -> 8.23 ms per grasp.",
                 "The first pick was 52 ms; before: 113 ms at load average 2.5.",
                 "Checked on 2026-12-02 against the issue's targets.",
                 "### History"):
        _append(copy / "docs" / "pick.md", line + "\n")
    found = {p.split(": ", 2)[1].split(" (")[0] for p in lab_log_problems(copy)}
    assert found == set(LAB_LOG), found


def test_paths_and_names_in_the_docs_exist(copy):
    assert reference_problems(ROOT) == []
    _append(copy / "docs" / "pick.md", "\nSee `grasplan/pick/nowhere.py` and `grasplan.pick.world.NoSuchThing`.\n")
    problems = reference_problems(copy)
    assert any("grasplan/pick/nowhere.py" in p for p in problems), problems
    assert any("grasplan.pick.world.NoSuchThing" in p for p in problems), problems


def readme_statuses(text: str) -> list[str]:
    """The plan statuses README's walkthrough lists (the backticked words of its status sentence)."""
    m = re.search(r"prints the grasps per status \(([^)]*)\)", text.replace("\n", " "))
    assert m, "README no longer has the sentence listing the plan statuses"
    return re.findall(r"`([a-z_]+)`", m.group(1).split(":")[0])


def test_readme_lists_every_plan_status():
    from grasplan.status import PLAN_STATUSES

    assert readme_statuses("x prints the grasps per status (`planned`, `no_path`: see) y") == ["planned", "no_path"]
    assert readme_statuses((ROOT / "README.md").read_text(encoding="utf-8")) == [str(s) for s in PLAN_STATUSES]
