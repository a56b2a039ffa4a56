"""``rmm-bench``'s command line as a whole: one subparser per subcommand, listed one line each in
``rmm-bench --help``; one meaning per flag in every subcommand (``rmm_bench.options``); old
spellings refused in one line; ``--env-opt`` reaching the run's configuration."""

from __future__ import annotations

import argparse
import json
import sqlite3

import pytest

from rmm_bench.cli import SUBCOMMANDS, build_parser, command_parser, main
from rmm_bench.options import _Refused, parse_env_opts

FAST = ["--clock", "fixed:1", "--workers", "1", "--no-progress", "--no-figure"]


def _help(parser: argparse.ArgumentParser, monkeypatch) -> str:
    monkeypatch.setenv("COLUMNS", "100")
    return parser.format_help()


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_the_top_help_lists_every_subcommand_on_one_line_each(monkeypatch):
    text = _help(build_parser(), monkeypatch)
    lines = text.splitlines()
    for name, (_, summary) in SUBCOMMANDS.items():
        (line,) = [line for line in lines if line.split()[:1] == [name]]
        assert line.split(None, 1)[1] == summary
    assert set(_subparsers()) == set(SUBCOMMANDS)
    assert len(lines) < 50


def test_no_subcommand_runs_and_a_bad_one_is_named(capsys):
    with pytest.raises(SystemExit) as e:
        main(["comapre", "x"])
    assert e.value.code == 2 and "invalid choice: 'comapre'" in capsys.readouterr().err


@pytest.mark.parametrize("name", list(SUBCOMMANDS))
def test_every_flag_has_help_and_one_meaning(name, monkeypatch):
    own = command_parser(name)
    sub = _subparsers()[name]
    assert [a.option_strings or [a.dest] for a in sub._actions] == [a.option_strings or [a.dest] for a in own._actions]
    for parser in (own, sub):
        assert "%%" not in _help(parser, monkeypatch)
        for a in parser._actions:
            if isinstance(a, _Refused):
                assert a.help == argparse.SUPPRESS and a.hint.startswith(("use ", "write "))
                continue
            assert a.help and a.help != argparse.SUPPRESS, (name, a.dest)
            if "--out" in a.option_strings:
                assert a.metavar == "DIR", name  # a directory everywhere
            if not a.option_strings and a.dest in ("results_dir", "results_dirs"):
                assert a.metavar == "DIR"
            if "--agents" in a.option_strings or "--env-kwargs" in a.option_strings:
                pytest.fail(f"{name} accepts {a.option_strings}")
    dests = {a.dest for a in own._actions if not isinstance(a, _Refused)}
    assert not dests & {"dir", "dirs", "agents", "env_kwargs"}, name


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["compare", "d", "--agents", "a,b"],
            "--agents is no longer accepted; use --agent (one agent or a comma list)",
        ),
        (["export", "d", "--agents", "a"], "--agents is no longer accepted; use --agent (one agent or a comma list)"),
        (["compare", "d", "--out", "x.md"], "--out is no longer accepted; write the table with --table FILE"),
        (["export", "d", "--out", "x.csv"], "--out is no longer accepted; write the table with --table FILE"),
        (["compare", "d", "--seed", "3"], "--seed is no longer accepted; use --bootstrap-seed"),
        (["riskmap", "--out", "x.png"], "--out is no longer accepted; write the figure with --png FILE"),
        (["riskmap", "--seed", "3"], "--seed is no longer accepted; use --world-seed"),
        (
            ["riskmap", "--kind", "honeycomb"],
            "--kind is no longer accepted; use --maze rectangular or --maze honeycomb",
        ),
        (["quadrisk", "--seed", "1"], "--seed is no longer accepted; use --world-seed"),
        (["calibrate", "--seed", "7"], "--seed is no longer accepted; use --world-seed"),
        (["--agent", "inactive", "--env-kwargs", "{}"], "--env-kwargs is no longer accepted; use --env-opt KEY=JSON"),
        (["check-system", "X-v0", "--env-kwargs", "{}"], "--env-kwargs is no longer accepted; use --env-opt KEY=JSON"),
        (["knob-sweep", "--agents", "lrmm"], "--agents is no longer accepted; use --agent (one guardian)"),
    ],
)
def test_old_spellings_are_refused_in_one_line(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rmm-bench: error: {message}") and err.count("\n") == 1


def test_env_opts_parse_and_name_what_is_wrong():
    assert parse_env_opts(["n_obstacles=3", 'maze_kind="mixed"', "x=[1, 2]"]) == {
        "n_obstacles": 3,
        "maze_kind": "mixed",
        "x": [1, 2],
    }
    assert parse_env_opts(None) == {}
    for items, message in [
        (["n_obstacles"], "--env-opt 'n_obstacles': expected KEY=JSON, e.g. maze_kind='\"mixed\"'"),
        (["=3"], "--env-opt '=3': expected KEY=JSON, e.g. maze_kind='\"mixed\"'"),
        (["kind=mixed"], "--env-opt 'kind=mixed': the value 'mixed' is not JSON (a string needs quotes)"),
        (["a=1", "a=2"], "--env-opt 'a=2': a is given twice; give each argument once"),
    ]:
        with pytest.raises(ValueError) as e:
            parse_env_opts(items)
        assert str(e.value) == message
    with pytest.raises(ValueError) as e:
        parse_env_opts(["b=1"], {"a", "c"}, "E-v0")
    assert str(e.value) == "--env-opt 'b=1': E-v0 takes no argument 'b'; it takes: a, c"


def _env_kwargs(out) -> list[dict]:
    con = sqlite3.connect(out / "results.db")
    try:
        return [json.loads(c)["env_kwargs"] for (c,) in con.execute("SELECT config FROM runs ORDER BY rowid")]
    finally:
        con.close()


def test_env_opts_reach_the_run_and_its_replay_verifies(tmp_path, capsys):
    out = tmp_path / "r"
    argv = ["--agent", "brakes", "--episodes", "2", "--env-opt", "n_obstacles=3", "--out", str(out), *FAST]
    assert main(argv) == 0
    assert _env_kwargs(out) == [{"base_step": 0.1, "clock": "fixed:1", "n_obstacles": 3, "time_accel": 10.0}]
    capsys.readouterr()
    assert main(["replay", str(out), "--agent", "brakes", "--episode", "0,1", "--no-progress"]) == 0
    assert "verified: 2 episodes of brakes" in capsys.readouterr().out


def test_a_run_without_env_opts_keeps_its_key(tmp_path):
    from rmm_bench.run_args import parse_run

    (run,) = parse_run(["--agent", "inactive", "--out", str(tmp_path), *FAST]).agent_runs().values()
    assert run.env_kwargs == {"base_step": 0.1, "clock": "fixed:1", "time_accel": 10.0}
    assert run.key == "3990ef051d980703"  # what every version before --env-opt stored


@pytest.mark.parametrize(
    "opt, message",
    [
        ("bogus=1", "--env-opt bogus=1: Dubins4DGuardedEnv.__init__() got an unexpected keyword argument 'bogus'"),
        ("n_obstacles=three", "--env-opt 'n_obstacles=three': the value 'three' is not JSON (a string needs quotes)"),
        ('clock="wall"', "--env-opt clock=...: set it with --clock, the command's own flag for it"),
        ("time_accel=2", "--env-opt time_accel=...: set it with --time-accel, the command's own flag for it"),
    ],
)
def test_a_bad_env_opt_is_one_line_and_exit_2(tmp_path, capsys, opt, message):
    out = tmp_path / "r"
    assert main(["--agent", "inactive", "--episodes", "1", "--env-opt", opt, "--out", str(out), *FAST]) == 2
    assert capsys.readouterr().err == f"rmm-bench: error: {message}\n"
    assert not (out / "results.db").exists()
