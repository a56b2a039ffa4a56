"""``rmm-bench riskmap`` and ``rmm-bench quadrisk``: the paper's Fig. 1 (riskmap) and Fig. 3 (quadrisk) as PNG files."""

from __future__ import annotations

import pytest

from benchmarks.bench.cli import main


def test_riskmap_command(tmp_path, capsys):
    out = tmp_path / "map.png"
    assert main(["riskmap", "--n", "60", "--out", str(out), "--dpi", "40"]) == 0
    assert out.stat().st_size > 1000
    assert main(["riskmap", "--n", "20", "--labels", "--kind", "honeycomb", "--out", str(out), "--dpi", "40"]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {out}: mean risk ")


def test_quadrisk_command(tmp_path):
    out = tmp_path / "q.png"
    assert main(["quadrisk", "--out", str(out), "--dpi", "40"]) == 0
    assert out.stat().st_size > 1000


@pytest.mark.parametrize("argv, message", [(["riskmap", "--n", "0"], "--n must be >= 1, got 0"),
                                           (["quadrisk", "--dpi", "0"], "--dpi must be >= 1, got 0")])
def test_bad_counts_exit_2_naming_the_flag(tmp_path, capsys, argv, message):
    assert main([*argv, "--out", str(tmp_path / "x.png")]) == 2
    assert capsys.readouterr().err == f"rmm-bench: error: {message}\n" and not (tmp_path / "x.png").exists()


def test_figure_commands_are_listed_in_rmm_bench_help():
    from benchmarks.bench.cli import build_parser

    text = build_parser().format_help()
    assert "rmm-bench riskmap --seed 3" in text and "rmm-bench quadrisk --seed 1" in text


def test_an_out_path_without_a_suffix_gets_png_and_the_message_names_the_file_written(tmp_path, capsys):
    assert main(["riskmap", "--n", "20", "--out", str(tmp_path / "res_fig"), "--dpi", "30"]) == 0
    assert (tmp_path / "res_fig.png").is_file() and not (tmp_path / "res_fig").exists()
    assert capsys.readouterr().out.startswith(f"wrote {tmp_path / 'res_fig.png'}: ")
