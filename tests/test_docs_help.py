"""The docs' option tables agree with ``--help``: where a row of a ``| option | default | ... |``
table in docs/*.md states a literal default (a number, a length such as ``0.1mm``, a name such as
``auto``, ``on``/``off``, ``required``) it is the default ``grasplan CMD --help`` prints (read from
the click command objects), and choices listed in the option cell (``--units mm\\|m\\|...\\|auto``)
are click's choices (all of them, or some with ``...``). Every option a row names must exist.

A table belongs to the command named in the nearest heading above it (`` `grasplan scene drop` ``),
else to the page's command (``plan.md`` -> ``plan``); a row may name its command first
(``plan --simulate N``). A descriptive default ("the gripper's", "one per core") is not compared."""
from __future__ import annotations

import importlib
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
import pytest

ROOT = Path(__file__).resolve().parent.parent

#: pages whose option table lists options shared by several commands (a row applies to each that has it)
SHARED_TABLES = {"quality.md": ("grasps", "plan", "simulate")}
NUMBER = re.compile(r"^(-?\d+(?:\.\d+)?(?:e-?\d+)?)\s*([a-zA-Z/^0-9]*)$")


def click_commands() -> dict[str, click.Command]:
    from grasplan.cli.group import COMMANDS

    out: dict[str, click.Command] = {}
    for name, (module, _) in COMMANDS.items():
        cmd = importlib.import_module(f"grasplan.cli.{module}").command
        if isinstance(cmd, click.Group):
            for sub, subcmd in cmd.commands.items():
                out[f"{name} {sub}"] = subcmd
        else:
            out[name] = cmd
    return out


@dataclass(frozen=True)
class Row:
    page: str
    lineno: int
    commands: tuple[str, ...]
    option_cell: str
    default_cell: str


def _cells(line: str) -> list[str]:
    line = line.strip().strip("|")
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line)]


def table_rows(root: Path, names: set[str]) -> list[Row]:
    rows = []
    for path in sorted((root / "docs").glob("*.md")):
        page = path.name
        own = page[:-3] if page[:-3] in names else None
        current = SHARED_TABLES.get(page) or ((own,) if own else ())
        lines = path.read_text().splitlines()
        fenced = False
        k = 0
        while k < len(lines):
            line = lines[k]
            if line.startswith("```"):
                fenced = not fenced
            elif not fenced and line.startswith("#"):
                found = [n for n in sorted(names, key=len, reverse=True) if f"`grasplan {n}`" in line]
                if found and page not in SHARED_TABLES:
                    current = (found[0],)
            elif not fenced and line.startswith("|") and k + 1 < len(lines) and re.match(r"^\|[-| :]+\|$", lines[k + 1]):
                head = [c.lower() for c in _cells(line)]
                if head and head[0] == "option" and "default" in head:
                    col = head.index("default")
                    k += 2
                    while k < len(lines) and lines[k].startswith("|"):
                        cells = _cells(lines[k])
                        if len(cells) > col:
                            rows.append(Row(page, k + 1, current, cells[0], cells[col]))
                        k += 1
                    continue
            k += 1
    return rows


def _params(cmd: click.Command, cell: str) -> list[click.Parameter]:
    """The click options a cell names, in order (``--blm / --no-blm`` is one)."""
    found: list[click.Parameter] = []
    for flag in re.findall(r"(?<![\w-])(--?[a-z][\w-]*)", cell):
        for p in cmd.params:
            if flag in (*p.opts, *getattr(p, "secondary_opts", ())) and p not in found:
                found.append(p)
    return found


def _flags(cell: str) -> list[str]:
    return re.findall(r"(?<![\w-])(--?[a-z][\w-]*)", cell)


def printed_default(cmd: click.Command, name: str, param: click.Parameter) -> str | None:
    """The ``[default: X]`` of the option's ``--help`` line (parentheses removed), or None."""
    record = param.get_help_record(click.Context(cmd, info_name=name))
    m = re.search(r"\[(?:[^\]]*; )?default: ([^;\]]*)", record[1]) if record else None
    if not m:
        return None
    text = m.group(1).strip()
    while text.startswith("(") and text.endswith(")"):
        text = text[1:-1].strip()
    return text


def _doc_literal(cell: str) -> str | None:
    """A doc default that names a value (else None: descriptive text, not compared)."""
    text = cell.replace("`", "").strip()
    text = re.sub(r"\s*\((?:deg|off|on|steel|plastic|aluminium)\)$", "", text).strip()
    text = re.sub(r"^\((required)\)$", r"\1", text)
    if NUMBER.match(text) or re.fullmatch(r"-?[\w.]+(?:,-?[\w.]+)*", text) or re.fullmatch(r"--[\w-]+", text):
        return text
    return None


def _as_bool(text: str) -> bool | None:
    t = text.lower().lstrip("-")
    if t in ("on", "true", "yes"):
        return True
    if t in ("off", "false", "no", "none", "0"):
        return False
    return None


def _same(doc: str, printed: str | None, param: click.Parameter) -> bool:
    default: Any = param.default
    if doc.lower() == "required":
        return bool(param.required)
    if isinstance(param, click.Option) and param.is_flag:
        want = bool(default) if isinstance(default, bool) else False
        if param.secondary_opts and doc.startswith("--"):
            return (doc in param.opts) == want
        b = _as_bool(doc)
        return b is not None and b == want
    if printed is None:
        if default is None or not isinstance(default, (int, float, str)):
            return doc.lower() in ("none", "-", "all", "off")  # no value: no limit, nothing
        printed = str(default)
    printed = re.sub(r"\s*\((?:off|on)\)$", "", printed)
    a, b = NUMBER.match(doc), NUMBER.match(printed)
    if a and b:
        same_number = float(a.group(1)) == float(b.group(1))
        units = {a.group(2).lower(), b.group(2).lower()} - {""}
        return same_number and len(units) <= 1
    return doc.lower() == printed.lower()


def _choices(cell: str) -> tuple[list[str], bool] | None:
    """Choices a cell lists after its option (``--units mm|m|...|auto``) and whether ``...`` is there."""
    m = re.search(r"--[\w-]+\s+([a-z0-9_.]+(?:\|[a-z0-9_.]+)+)", cell.replace("`", ""))
    if not m:
        return None
    words = m.group(1).split("|")
    return [w for w in words if w != "..."], "..." in words


def click_choices(param: click.Parameter) -> list[str] | None:
    """The choices ``--help`` shows for an option: a click.Choice or a ``choice`` option spec."""
    if isinstance(param.type, click.Choice):
        return [str(c) for c in param.type.choices]
    spec = getattr(param.type, "spec", None)
    if spec is not None and spec.kind == "choice":
        return [str(c) for c in spec.choices]
    return None


def help_problems(root: Path, commands: dict[str, click.Command] | None = None) -> tuple[list[str], int]:
    """Disagreements between the docs' tables and --help, and how many defaults were compared."""
    commands = commands or click_commands()
    problems, compared = [], 0
    for row in table_rows(root, set(commands)):
        where = f"docs/{row.page}:{row.lineno}"
        names = row.commands
        first = row.option_cell.replace("`", "").split()
        if first and first[0] in commands:
            names = (first[0],)
        for name in names:
            cmd = commands[name]
            params = _params(cmd, row.option_cell)
            missing = [f for f in _flags(row.option_cell) if not any(
                f in (*p.opts, *getattr(p, "secondary_opts", ())) for p in cmd.params)]
            if missing and row.page not in SHARED_TABLES:
                problems.append(f"{where}: grasplan {name} has no option {', '.join(missing)}")
            if not params:
                continue
            parts = [row.default_cell] if len(params) == 1 else re.split(r",\s+|\s+/\s+", row.default_cell)
            if len(parts) == len(params):
                for param, part in zip(params, parts):
                    doc = _doc_literal(part)
                    if doc is None:
                        continue
                    compared += 1
                    printed = printed_default(cmd, name, param)
                    if not _same(doc, printed, param):
                        shown = printed if printed is not None else f"none printed (default {param.default!r})"
                        problems.append(f"{where}: grasplan {name} {param.opts[-1]}: docs say default {doc!r}, "
                                        f"--help says {shown}")
            listed = _choices(row.option_cell)
            real = click_choices(params[0]) if listed and len(params) == 1 else None
            if listed and real is not None:
                words, partial = listed
                if (not set(words) <= set(real)) or (not partial and set(words) != set(real)):
                    problems.append(f"{where}: grasplan {name} {params[0].opts[-1]}: docs list choices "
                                    f"{'|'.join(words)}{'|...' if partial else ''}, --help has {'|'.join(real)}")
    return problems, compared


def synopsis_problems(root: Path, commands: dict[str, click.Command] | None = None) -> tuple[list[str], int]:
    """Choices a page's synopsis block lists (``grasplan plan PART ... [--units mm|m|auto]``) against
    --help's: all of them, or some followed by ``...``."""
    commands = commands or click_commands()
    problems, compared = [], 0
    for path in sorted((root / "docs").glob("*.md")):
        text = path.read_text()
        for m in re.finditer(r"^```\w*\n(grasplan .*?)^```", text, flags=re.M | re.S):
            block = m.group(1)
            words = block.split()
            name = " ".join(words[1:3]) if words[1:2] == ["scene"] else words[1]
            if name not in commands or not re.search(r"\s\[--", block):
                continue  # not a synopsis
            lineno = text[:m.start()].count("\n") + 2
            for opt, listed in re.findall(r"(--[\w-]+)[ =]([a-z0-9_.-]+(?:\|[a-z0-9_.-]+)+)", block):
                params = _params(commands[name], opt)
                real = click_choices(params[0]) if params else None
                if real is None:
                    continue
                choices = listed.split("|")
                partial = "..." in choices
                choices = [c for c in choices if c != "..."]
                compared += 1
                if not set(choices) <= set(real) or (not partial and set(choices) != set(real)):
                    problems.append(f"docs/{path.name}:{lineno}: grasplan {name} {opt}: the synopsis lists "
                                    f"{listed}, --help has {'|'.join(real)} (list them all, or end with |...)")
    return problems, compared


@pytest.fixture()
def copy(tmp_path):
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    return tmp_path


def test_docs_tables_match_help():
    problems, compared = help_problems(ROOT)
    assert problems == [], "\n".join(problems)
    assert compared >= 60, compared  # the tables are found and read


def test_synopsis_choices_match_help():
    problems, compared = synopsis_problems(ROOT)
    assert problems == [], "\n".join(problems)
    assert compared >= 5, compared


def test_a_doctored_synopsis_fails(copy):
    path = copy / "docs" / "blm.md"
    path.write_text(path.read_text().replace("[--units auto|m|mm|...]", "[--units auto|m|mm|furlong]", 1))
    problems, _ = synopsis_problems(copy)
    assert any("blm.md" in p and "--units" in p for p in problems), problems


def test_a_doctored_copy_fails(copy):
    """Wrong defaults, wrong choices and a made-up option in a copy of the docs are each reported."""
    for page, old, new in (("candidates.md", "| `--alpha` | `0.1mm` |", "| `--alpha` | `0.2mm` |"),
                           ("clutter.md", "`--decomposition coacd\\|hull`", "`--decomposition coacd\\|hull\\|vhacd`"),
                           ("serve.md", "| `--port` | `8765` |", "| `--port` | `8080` |"),
                           ("grasps.md", "| `--roll-step` | 15 |", "| `--roll-stride` | 15 |"),
                           ("quality.md", "| `--density KG_M3` | 7850 (steel) |", "| `--density KG_M3` | 2700 |")):
        path = copy / "docs" / page
        text = path.read_text()
        assert old in text, (page, old)
        path.write_text(text.replace(old, new, 1))
    problems, _ = help_problems(copy)
    joined = "\n".join(problems)
    for expect in ("candidates --alpha: docs say default '0.2mm'", "scene drop --decomposition: docs list choices",
                   "serve --port: docs say default '8080'", "grasps has no option --roll-stride",
                   "--density: docs say default '2700'"):
        assert expect in joined, joined
