"""Output folders are published only when complete (io/outputs.atomic_directory; itl, paper, discrepancy)."""

from __future__ import annotations

import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.errors import OutputPathError
from fuelhm_bench.io.outputs import MANIFEST, atomic_directory


def test_new_directory_appears_only_on_success(tmp_path):
    out = tmp_path / "out"
    with atomic_directory(out) as tmp:
        (tmp / "a.txt").write_text("a")
        (tmp / "sub").mkdir()
        (tmp / "sub" / "b.csv").write_text("b")
        assert not out.exists()
    assert (out / "a.txt").read_text() == "a" and (out / "sub" / "b.csv").read_text() == "b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary folder left
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "a.txt", "sub"]


@pytest.mark.parametrize("error", [KeyboardInterrupt, RuntimeError])
def test_interrupted_run_publishes_nothing_and_keeps_the_old_content(tmp_path, error):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.txt").write_text("old")
    with pytest.raises(error):
        with atomic_directory(out) as tmp:
            (tmp / "a.txt").write_text("new")
            (tmp / "b.txt").write_text("new")
            raise error()
    assert sorted(p.name for p in out.iterdir()) == ["a.txt"] and (out / "a.txt").read_text() == "old"
    assert not (out / MANIFEST).exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    with pytest.raises(error):  # a new folder is not even created
        with atomic_directory(tmp_path / "new") as tmp:
            (tmp / "a.txt").write_text("new")
            raise error()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_existing_directory_keeps_other_files_and_refuses_without_force(tmp_path):
    out = tmp_path / "out"
    (out / "sub").mkdir(parents=True)
    (out / "mine.txt").write_text("mine")
    (out / "sub" / "old.csv").write_text("old")
    (out / "a.txt").write_text("old")
    with atomic_directory(out, force=True) as tmp:  # a.txt and sub/ are the user's: replaced only with force
        (tmp / "a.txt").write_text("new")
        (tmp / "sub").mkdir()
        (tmp / "sub" / "new.csv").write_text("new")
    assert (out / "mine.txt").read_text() == "mine" and (out / "a.txt").read_text() == "new"
    assert sorted(p.name for p in (out / "sub").iterdir()) == ["new.csv", "old.csv"]
    with pytest.raises(OutputPathError, match="already holds a.txt; refusing to overwrite"):
        with atomic_directory(out, force=False, names=("a.txt",)):
            pass
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(OutputPathError, match="is a file, not a directory"):
        with atomic_directory(blocker / "out"):
            pass


def test_itl_is_refused_above_the_run_budget_before_any_output(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("FUELHM_RUN_BUDGET_FLIGHT_HOURS", "10")
    out = tmp_path / "itl"
    assert main(["itl", "--units", "100", "--minutes", "30", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--units 100 x 29 cases (healthy + 7 modes x 4 intensities) + --healthy-units 8 x --healthy-flights 5 = " \
           "2940 flights of 30 min is 1470 flight-hours" in err
    assert "above the run budget of 10 flight-hours" in err and "FUELHM_RUN_BUDGET_FLIGHT_HOURS=1470" in err
    assert not out.exists()


def test_a_run_again_replaces_its_own_files_but_not_the_users(tmp_path):
    """Before, a command writing into an existing folder (itl, paper) replaced a same-named file the user
    had there (their own table.md) without --force; refusing every existing file instead would make a
    command refuse to refresh its own output."""
    out = tmp_path / "out"
    with atomic_directory(out) as tmp:
        (tmp / "table.md").write_text("run 1")
    with atomic_directory(out) as tmp:  # the same command again: its own file, no --force needed
        (tmp / "table.md").write_text("run 2")
    assert (out / "table.md").read_text() == "run 2"
    (out / "notes.md").write_text("the user's")
    with pytest.raises(OutputPathError, match=r"already holds notes.md, not written by fuelhm-bench; refusing to "
                                              r"replace \(pass --force"):
        with atomic_directory(out) as tmp:
            (tmp / "table.md").write_text("run 3")
            (tmp / "notes.md").write_text("overwritten")
    assert (out / "notes.md").read_text() == "the user's" and (out / "table.md").read_text() == "run 2"
    with atomic_directory(out, force=True) as tmp:
        (tmp / "notes.md").write_text("replaced on purpose")
    assert (out / "notes.md").read_text() == "replaced on purpose"


@pytest.mark.parametrize("command, module, heavy, name", [
    (["itl", "--units", "1", "--intensities", "0.5,1", "--minutes", "2"], "fuelhm_bench.datasets.knowledge", "build_knowledge",
     "signatures.md"),
    (["paper", "--doe-units", "1"], "fuelhm_bench.benchmark.paper", "run_paper", "report.md"),
])
def test_a_users_file_is_refused_before_the_work(tmp_path, capsys, monkeypatch, command, module, heavy, name):
    """Before, itl and paper simulated for minutes, then refused to publish over the user's file of the same name."""
    import importlib

    def never(*args, **kwargs):
        raise AssertionError(f"{heavy} ran although the output folder was refused")

    monkeypatch.setattr(importlib.import_module(module), heavy, never)
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_text("the user's")
    assert main([*command, "--out", str(out)]) == 2
    assert f"already holds {name}, not written by fuelhm-bench; refusing" in capsys.readouterr().err
    assert (out / name).read_text() == "the user's"
