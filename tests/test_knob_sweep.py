"""``rmm-bench knob-sweep`` (rmm_bench.knob_sweep): one rmm-bench run per knob value, a table and a figure."""

from __future__ import annotations

import pytest

from rmm_bench.cli import main


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--agent", "random", "--knob", "p_active", "--values", "0,x"], "--values must be comma-separated JSON"),
        (["--agent", "random", "--knob", "p_active", "--values", ","], "--values is empty"),
        (["--agent", "random", "--knob", "p_active", "--values", "0", "--episodes", "0"], "--episodes must be >= 1"),
    ],
)
def test_bad_arguments_exit_2_naming_the_flag(argv, message, tmp_path, capsys):
    assert main(["knob-sweep", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rmm-bench knob-sweep: error: ") and err.count("\n") == 1 and message in err


def test_sweep_runs_each_value_and_marks_the_default(tmp_path):
    rc = main(
        [
            "knob-sweep",
            "--agent",
            "random",
            "--knob",
            "p_active",
            "--values",
            "0,1",
            "--default",
            "1.0",
            "--episodes",
            "2",
            "--workers",
            "1",
            "--no-reference",
            "--out",
            str(tmp_path),
        ]
    )
    assert rc == 0
    md = (tmp_path / "random_p_active.md").read_text().splitlines()
    rows = [line for line in md if line.startswith("| 0") or line.startswith("| 1")]
    assert len(rows) == 2
    # p_active = 0 never takes control; p_active = 1 always does (after the driver's first lap)
    assert rows[0].split("|")[5].strip().startswith("0.0 ")
    assert float(rows[1].split("|")[5].split("±")[0]) > 90.0
    assert "(default)" in rows[1] and "(default)" not in rows[0]
    assert (tmp_path / "random_p_active.png").stat().st_size > 1000
    assert "Command: `rmm-bench knob-sweep --agent random --knob p_active" in "\n".join(md)


def test_a_bad_knob_is_the_runs_own_one_line_and_exit_2(tmp_path, capsys):
    argv = [
        "knob-sweep",
        "--agent",
        "random",
        "--knob",
        "nope",
        "--values",
        "1",
        "--episodes",
        "1",
        "--out",
        str(tmp_path),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nope" in err, err
