"""``rmm-bench riskmap`` and ``rmm-bench quadrisk``: the paper's Fig. 1 (riskmap) and Fig. 3 (quadrisk) as PNG files."""

from __future__ import annotations

import pytest

from rmm_bench.cli import main


def test_riskmap_command(tmp_path, capsys):
    out = tmp_path / "map.png"
    assert main(["riskmap", "--n", "60", "--png", str(out), "--dpi", "40"]) == 0
    assert out.stat().st_size > 1000
    assert main(["riskmap", "--n", "20", "--labels", "--maze", "honeycomb", "--png", str(out), "--dpi", "40"]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {out}: mean risk ")


def test_quadrisk_command(tmp_path):
    out = tmp_path / "q.png"
    assert main(["quadrisk", "--png", str(out), "--dpi", "40"]) == 0
    assert out.stat().st_size > 1000


@pytest.mark.parametrize(
    "argv, message",
    [(["riskmap", "--n", "0"], "--n must be >= 1, got 0"), (["quadrisk", "--dpi", "0"], "--dpi must be >= 1, got 0")],
)
def test_bad_counts_exit_2_naming_the_flag(tmp_path, capsys, argv, message):
    assert main([*argv, "--png", str(tmp_path / "x.png")]) == 2
    assert capsys.readouterr().err == f"rmm-bench: error: {message}\n" and not (tmp_path / "x.png").exists()


def test_figure_commands_are_listed_in_rmm_bench_help():
    from rmm_bench.cli import build_parser

    text = build_parser().format_help()
    assert "rmm-bench riskmap --world-seed 3" in text
    lines = text.splitlines()
    assert any(line.split() and line.split()[0] == "riskmap" for line in lines)
    assert any(line.split() and line.split()[0] == "quadrisk" for line in lines)


def test_an_out_path_without_a_suffix_gets_png_and_the_message_names_the_file_written(tmp_path, capsys):
    assert main(["riskmap", "--n", "20", "--png", str(tmp_path / "res_fig"), "--dpi", "30"]) == 0
    assert (tmp_path / "res_fig.png").is_file() and not (tmp_path / "res_fig").exists()
    assert capsys.readouterr().out.startswith(f"wrote {tmp_path / 'res_fig.png'}: ")


def test_no_figure_writes_the_tables_removes_a_stale_figure_and_report_draws_it(tmp_path):
    out = tmp_path / "r"
    out.mkdir()
    (out / "outcomes.png").write_bytes(b"a figure of an earlier run")
    argv = [
        "--agent",
        "inactive",
        "--episodes",
        "2",
        "--workers",
        "1",
        "--clock",
        "fixed:1",
        "--no-progress",
        "--out",
        str(out),
    ]
    assert main([*argv, "--no-figure"]) == 0
    assert (out / "table_I.md").read_text().count("| inactive |") == 1
    assert not (out / "outcomes.png").exists()  # it would not have matched the table
    assert main(["report", str(out)]) == 0
    assert (out / "outcomes.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_sweep_without_a_figure_writes_its_table_only(tmp_path):
    out = tmp_path / "s"
    out.mkdir()
    (out / "latency_sweep.png").write_bytes(b"stale")
    assert (
        main(
            [
                "sweep",
                "--agent",
                "inactive",
                "--latency",
                "0,5",
                "--episodes",
                "2",
                "--workers",
                "1",
                "--no-progress",
                "--no-figure",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert "| inactive |" in (out / "latency_sweep.md").read_text()
    assert not (out / "latency_sweep.png").exists()
