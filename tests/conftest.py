"""Shared fixtures. Paper parts come from ../shared/parts/paper (never copied into this repo);
tests that need them skip with a clear reason when the folder is absent."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
EXAMPLE_PARTS = EXAMPLES / "parts"
PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
PAPER_PARTS = ["IPAGearShaft.stl", "IPARingScrew.stl", "SileaneBunny.obj", "SileaneGear.stl",
               "SileanePepper.stl", "TLess20.stl", "TLess22.stl"]
SHARP_PAPER_PARTS = [p for p in PAPER_PARTS if p != "SileaneBunny.obj"]


@pytest.fixture(scope="session", autouse=True)
def _cache_folder(tmp_path_factory):
    """One cache folder per test process: grasp databases start empty (the first plan of a part
    computes its database, later plans read it) and never reach the user's cache. The convex
    decompositions (minutes per paper part, a pure function of the mesh) stay shared with the
    user's cache. Tests of the cache itself set their own folder."""
    from grasplan.cache import cache_dir

    old = os.environ.get("GRASPLAN_CACHE_DIR")
    user = cache_dir()
    folder = tmp_path_factory.mktemp("cache")
    try:
        (user / "coacd").mkdir(parents=True, exist_ok=True)
        (folder / "coacd").symlink_to(user / "coacd", target_is_directory=True)
    except OSError:  # no writable user cache: the decompositions are computed in the session folder
        (folder / "coacd").mkdir(exist_ok=True)
    os.environ["GRASPLAN_CACHE_DIR"] = str(folder)
    yield
    if old is None:
        os.environ.pop("GRASPLAN_CACHE_DIR", None)
    else:
        os.environ["GRASPLAN_CACHE_DIR"] = old


def paper_part(name: str) -> Path:
    """Path of a paper part, or skip the test with the reason."""
    path = PAPER_DIR / name
    if not path.exists():
        pytest.skip(f"paper part {name} not found in {PAPER_DIR} (the evaluation parts live outside this repo; "
                    f"set GRASPLAN_PAPER_PARTS to their folder)")
    return path


@pytest.fixture
def paper():
    """``paper("TLess20.stl")`` -> Path, or skip."""
    return paper_part


@pytest.fixture(scope="session")
def example_part():
    def get(name: str) -> Path:
        return EXAMPLE_PARTS / name
    return get


def pytest_terminal_summary(terminalreporter):
    """Lines a test recorded with ``record_property("summary", text)`` (e.g. the service load
    test's p50/p95), printed after the run, also from pytest-xdist workers."""
    lines = [v for rep in terminalreporter.stats.get("passed", []) for k, v in getattr(rep, "user_properties", ())
             if k == "summary"]
    if lines:
        terminalreporter.section("summaries")
        for line in lines:
            terminalreporter.write_line(str(line))
