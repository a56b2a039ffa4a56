"""Results files that never lose data: no command writes over what it reads (or over any
SQLite database), two merges into one OUT never both succeed, results in a read-only folder
stay readable and read-only commands leave nothing beside them, and unusable files are named
as such in one line (docs/comparing.md, rmm_bench.outputs)."""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import sqlite3
import subprocess
from pathlib import Path

import pytest

import rmm_bench.outputs as outputs
from rmm_bench.cli import main
from rmm_bench.merge import MergeConflict, merge
from rmm_bench.outputs import OutputExists, check_output, publish, write_output

RUN = ["--agent", "inactive,brakes", "--episodes", "3", "--clock", "fixed:1", "--workers", "1", "--no-progress"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("files")
    assert main([*RUN, "--out", str(root / "a")]) == 0
    assert main([*RUN, "--shard", "1/2", "--out", str(root / "s1")]) == 0
    assert main([*RUN, "--shard", "2/2", "--out", str(root / "s2")]) == 0
    return root


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _copy(runs: Path, name: str, tmp_path: Path) -> Path:
    out = tmp_path / name
    shutil.copytree(runs / name, out)
    return out


def _refused(capsys, argv: list[str], *words: str) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert ".tmp" not in err and "merging-" not in err, err  # temporary names are never shown
    for w in words:
        assert w in err, err
    return err


# 1. no output over a file the command reads, nor over any SQLite database


@pytest.mark.parametrize(
    "argv",
    [
        ["export", "{d}", "--format", "csv", "--table", "{d}/results.db"],
        ["export", "{d}", "--format", "parquet", "--table", "{d}/results.db"],
        ["export", "{d}/results.db", "--format", "csv", "--table", "{d}/results.db-wal"],
        ["compare", "{d}", "--agent", "inactive,brakes", "--table", "{d}/results.db"],
        ["report", "{d}", "--html", "{d}/results.db"],
    ],
    ids=["export-csv", "export-parquet", "export-onto-wal", "compare", "report-html"],
)
def test_no_command_writes_over_the_database_it_reads(runs, tmp_path, capsys, argv):
    d = _copy(runs, "a", tmp_path)
    before = _sha(d / "results.db")
    _refused(capsys, [a.format(d=d) for a in argv], "results.db", "choose another file")
    assert _sha(d / "results.db") == before
    assert sorted(p.name for p in d.iterdir() if p.name.startswith(".")) == []
    assert main(["replay", str(d), "--agent", "inactive", "--episode", "0"]) == 0  # still a results database


def test_no_command_writes_over_another_database_nor_through_a_link(runs, tmp_path, capsys):
    d = _copy(runs, "a", tmp_path)
    other = tmp_path / "other.csv"  # a results database under another name
    shutil.copy(runs / "s1" / "results.db", other)
    before = _sha(other)
    _refused(capsys, ["export", str(d), "--format", "csv", "--table", str(other)], "SQLite database")
    _refused(capsys, ["compare", str(d), "--agent", "inactive,brakes", "--table", str(other)], "SQLite database")
    assert _sha(other) == before
    link = tmp_path / "table.md"
    link.symlink_to(d / "results.db")  # the database under a name that looks like an output
    _refused(capsys, ["compare", str(d), "--agent", "inactive,brakes", "--table", str(link)], "reads")
    video = tmp_path / "ep.gif"
    shutil.copy(runs / "s1" / "results.db", video)
    _refused(capsys, ["replay", str(d), "--agent", "inactive", "--episode", "0", "--video", str(video)], "SQLite")
    assert _sha(video) == before


def test_outputs_go_into_new_folders_and_existing_outputs_are_replaced(runs, tmp_path, capsys):
    d = _copy(runs, "a", tmp_path)
    out = tmp_path / "new" / "deeper" / "eps.parquet"  # a folder not made yet, as --frames makes its own
    assert main(["export", str(d), "--table", str(out)]) == 0
    assert out.is_file()
    csv = tmp_path / "eps.csv"
    csv.write_text("an earlier export\n")
    assert main(["export", str(d), "--format", "csv", "--table", str(csv)]) == 0  # a previous output is replaced
    assert csv.read_text().startswith("schema,")
    video = tmp_path / "videos" / "ep0.gif"
    assert main(["replay", str(d), "--agent", "inactive", "--episode", "0", "--video", str(video), "--size", "64"]) == 0
    assert video.is_file() and video.read_bytes()[:3] == b"GIF"
    capsys.readouterr()
    _refused(capsys, ["export", str(d), "--table", str(tmp_path)], "is a folder", str(tmp_path))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_publish_never_replaces_a_file_that_appeared_meanwhile(tmp_path):
    target = tmp_path / "t.md"
    tmp = tmp_path / ".t.md.1.tmp"
    tmp.write_text("mine")
    target.write_text("theirs")  # written by another command after this one checked the name
    with pytest.raises(OutputExists, match="appeared while this command ran"):
        publish(tmp, target, existed=False)
    assert target.read_text() == "theirs" and not tmp.exists()
    write_output(target, lambda p: p.write_text("replaced"), existed=True)
    assert target.read_text() == "replaced"
    with pytest.raises(ValueError, match="it is a folder"):
        check_output(tmp_path, "--out")


# 2. two merges into one OUT


def test_a_merge_whose_output_appeared_meanwhile_fails_and_keeps_the_other(runs, tmp_path, monkeypatch):
    out = tmp_path / "m"
    real_link = os.link

    def racing_link(src, dst):  # the other merge finishes first, just before this one moves its file
        if Path(dst).name == "results.db" and not Path(dst).exists():
            shutil.copy(runs / "a" / "results.db", dst)
        return real_link(src, dst)

    monkeypatch.setattr(outputs.os, "link", racing_link)
    with pytest.raises(MergeConflict, match="appeared while this merge ran"):
        merge(out, [runs / "s1", runs / "s2"])
    assert _sha(out / "results.db") == _sha(runs / "a" / "results.db")  # the other merge's result is intact
    assert [p.name for p in out.iterdir()] == ["results.db"]


@pytest.mark.slow
def test_two_merges_started_together_never_both_succeed(runs, tmp_path):
    """The probe's trial, for real: two `rmm-bench merge` processes into one OUT, seven times."""
    exe = Path(os.environ.get("VIRTUAL_ENV", Path(os.sys.executable).parent.parent)) / "bin" / "rmm-bench"
    exe = exe if exe.exists() else Path(shutil.which("rmm-bench") or "rmm-bench")
    for trial in range(7):
        out = tmp_path / f"m{trial}"
        procs = [
            subprocess.Popen(
                [str(exe), "merge", str(runs / a), str(runs / b), "--out", str(out)], stderr=subprocess.PIPE
            )
            for a, b in (("s1", "s2"), ("a", "s1"))
        ]
        codes = [p.wait(120) for p in procs]
        assert sorted(codes) in ([0, 2], [2, 2], [0, 1]), codes
        assert codes.count(0) <= 1
        if 0 in codes:
            with sqlite3.connect(out / "results.db") as con:
                assert con.execute("SELECT COUNT(*) FROM parts").fetchone()[0] == 2


def test_what_a_killed_merge_left_is_removed_by_the_next(runs, tmp_path):
    out = tmp_path / "m"
    out.mkdir()
    dead = subprocess.Popen(["true"])
    dead.wait()
    for suffix in ("", "-wal", "-shm", "-journal"):
        (out / f".results.db.merging-{dead.pid}{suffix}").write_bytes(b"half")
    merge(out, [runs / "s1", runs / "s2"])
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []


@pytest.mark.slow
def test_a_merge_killed_with_sigkill_leaves_nothing_the_next_merge_keeps(runs, tmp_path):
    out = tmp_path / "m"
    code = (
        "import os, rmm_bench.outputs as o\n"
        "def die(*a): os.kill(os.getpid(), 9)\n"
        "o.os.link = die\n"
        "from rmm_bench.merge import merge\n"
        f"merge({str(out)!r}, [{str(runs / 's1')!r}, {str(runs / 's2')!r}])\n"
    )
    proc = subprocess.run([os.sys.executable, "-c", code], check=False)
    assert proc.returncode == -9
    assert any(p.name.startswith(".results.db.merging-") for p in out.iterdir())
    merge(out, [runs / "s1", runs / "s2"])
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []


# 3. read-only folders, and nothing left beside a database a command only read


@contextlib.contextmanager
def _read_only_copy(src: Path, parent: Path):
    """``src`` copied into a folder this process cannot write: a read-only tmpfs when running as
    root (root writes through permission bits), the permission bits otherwise."""
    folder = parent / "ro"
    folder.mkdir()
    if os.geteuid() == 0:
        if subprocess.run(["mount", "-t", "tmpfs", "none", str(folder)], capture_output=True).returncode != 0:
            pytest.skip("running as root without the right to mount a read-only file system")
        try:
            shutil.copytree(src, folder / "r")
            subprocess.run(["mount", "-o", "remount,ro", str(folder)], check=True)
            yield folder / "r"
        finally:
            subprocess.run(["umount", str(folder)], check=False)
    else:
        shutil.copytree(src, folder / "r")
        os.chmod(folder / "r", 0o555)
        try:
            yield folder / "r"
        finally:
            os.chmod(folder / "r", 0o755)


def _legacy_wal(db: Path) -> None:
    """Put ``db`` back in WAL mode, as every run left its database before this change."""
    con = sqlite3.connect(db)
    con.execute("PRAGMA journal_mode=WAL")
    con.close()
    assert db.read_bytes()[18:20] == b"\x02\x02" and not Path(f"{db}-wal").exists()


@pytest.mark.parametrize("legacy_wal", [False, True], ids=["finished-run", "legacy-wal"])
def test_results_in_a_read_only_folder_are_readable_by_every_read_only_command(runs, tmp_path, capsys, legacy_wal):
    src = _copy(runs, "a", tmp_path)
    if legacy_wal:
        _legacy_wal(src / "results.db")
    elsewhere = tmp_path / "w"
    with _read_only_copy(src, tmp_path) as d:
        before = sorted(p.name for p in d.iterdir())
        assert main(["replay", str(d), "--agent", "brakes", "--episode", "0,2"]) == 0
        assert main(["compare", str(d), "--agent", "inactive,brakes"]) == 0
        assert main(["export", str(d), "--table", str(elsewhere / "e.parquet")]) == 0
        assert main(["report", str(d), "--html", str(elsewhere / "page.html")]) == 0
        assert "is read-only" in capsys.readouterr().err
        assert main(["merge", str(d), "--out", str(elsewhere / "m")]) == 0
        assert sorted(p.name for p in d.iterdir()) == before
    assert (elsewhere / "page.html").is_file() and (elsewhere / "m" / "results.db").is_file()


@pytest.mark.parametrize("legacy_wal", [False, True], ids=["finished-run", "legacy-wal"])
def test_read_only_commands_leave_no_files_beside_the_database(runs, tmp_path, legacy_wal):
    d = _copy(runs, "a", tmp_path)
    if legacy_wal:
        _legacy_wal(d / "results.db")
    sha = _sha(d / "results.db")
    assert main(["replay", str(d), "--agent", "inactive", "--episode", "1"]) == 0
    assert main(["compare", str(d), "--agent", "inactive,brakes"]) == 0
    assert main(["export", str(d), "--table", str(tmp_path / "e.parquet")]) == 0
    assert main(["merge", str(d), "--out", str(tmp_path / "m")]) == 0
    assert not [p.name for p in d.iterdir() if p.name.endswith(("-wal", "-shm", "-journal"))]
    assert _sha(d / "results.db") == sha


def test_a_finished_run_leaves_one_self_contained_file(runs):
    for name in ("a", "s1", "s2"):
        db = runs / name / "results.db"
        assert db.read_bytes()[18:20] == b"\x01\x01"  # rollback-journal mode: no -wal/-shm needed to read it
        assert not Path(f"{db}-wal").exists() and not Path(f"{db}-shm").exists()


# 4. files that are no results database


@pytest.mark.parametrize("what", ["empty", "foreign"])
def test_an_empty_or_foreign_database_is_named_in_one_line(tmp_path, capsys, what):
    d = tmp_path / "r"
    d.mkdir()
    db = d / "results.db"
    if what == "empty":
        db.touch()
        words = ["is empty (0 bytes)", "not a results database"]
    else:
        with sqlite3.connect(db) as con:
            con.execute("CREATE TABLE notes (text TEXT)")
        words = ["not a results database", "no runs or episodes table"]
    for argv in (
        ["replay", str(d), "--agent", "inactive", "--episode", "0"],
        ["compare", str(d), "--agent", "inactive,brakes"],
        ["export", str(d), "--table", str(tmp_path / "e.csv"), "--format", "csv"],
        ["merge", str(d), "--out", str(tmp_path / "m")],
        ["report", str(d)],
    ):
        err = _refused(capsys, argv, str(db), *words)
        assert "intact" not in err and "OperationalError" not in err
    assert not (tmp_path / "e.csv").exists() and not (tmp_path / "m" / "results.db").exists()
