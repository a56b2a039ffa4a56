"""``rmm-bench collisions`` (benchmarks/bench/collisions.py): a guardian's collisions classified
by replaying them, from hand-built steps (each class, the window, a guardian without an alarm)
and end to end on a trimmed copy of the shipped Dubins4D reference results (every replay
verified); bad input is one line naming the value, exit 2."""

from __future__ import annotations

import json
import math
import shutil
import sqlite3
import tempfile
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.collision_classes import CLASSES, AlarmLog, classify, onset, versus_lead

REFERENCE = Path(__file__).resolve().parents[1] / "benchmarks" / "bench" / "reference"
THRESHOLD = 0.5


class Scripted:
    """A guardian's stand-in: ``alarm()`` plays back a scripted signal, one value per step."""

    def __init__(self, values):
        self.values = list(values)
        self.k = -1

    def alarm(self):
        self.k += 1
        v = self.values[self.k]
        return None if v is None else (v, THRESHOLD)


class Silent:
    """A third-party guardian without the hook."""


def _log(guardian, control: str, dt: float = 0.1) -> AlarmLog:
    """Steps logged as a replay logs them: ``control`` one character per step (``G`` guardian, ``.`` driver)."""
    log = AlarmLog()
    log.begin(env=None)
    for k, c in enumerate(control, 1):
        log.step({"active": c == "G", "sim_time": round(k * dt, 10)}, guardian)
    return log


def _class(values, control, doomed=False, last_steps=2, window=None):
    log = _log(Scripted(values) if values is not None else Silent(), control)
    return classify(log.active, log.alarms, log.times, doomed, last_steps, window)


def test_each_class_from_a_scripted_signal_and_control_log():
    lo, hi = 0.1, 0.9
    # the alarm first up within the last 2 steps: unseen, even with the guardian in control at impact
    assert _class([lo] * 6 + [hi, hi], "......GG")[0] == "unseen"
    # up at step 2, in control from there to impact: a failed manoeuvre, 0.6 s from the alarm's decision
    cls, m = _class([lo, lo, hi, hi, hi, hi, hi, hi], "..GGGGGG")
    assert cls == "failed manoeuvre"
    assert m["first"] == 2 and m["alarm_to_impact_s"] == pytest.approx(0.6) and m["in_control_at_impact"]
    # up and in control, then control handed back before impact
    assert _class([lo, hi, hi, lo, lo, lo, lo, hi], ".GG.....")[0] == "released"
    # up in time, never in control after it
    assert _class([lo, hi, hi, hi, hi, hi, hi, hi], "........")[0] == "alarm ignored"
    # a doomed start comes first, whatever the steps
    assert _class([hi] * 8, "GGGGGGGG", doomed=True)[0] == "doomed"
    # the peak before the last steps: the highest value there and its threshold
    _, m = _class([0.2, 0.3, 0.25, lo, lo, lo, hi, hi], "......GG")
    assert (m["peak_before"], m["threshold"]) == (0.3, THRESHOLD)
    assert set(CLASSES) == {"doomed", "unseen", "failed manoeuvre", "released", "alarm ignored"}


def test_nan_is_not_an_alarm_and_the_window_leaves_earlier_dangers_out():
    nan = math.nan
    assert _class([nan] * 6 + [0.9, 0.9], "......GG")[0] == "unseen"
    # an alarm that went down long before: in the whole episode it counts, within 0.3 s it does not
    values, control = [0.9, 0.9] + [0.1] * 8 + [0.9], "GG.........G"[:11]
    assert _class(values, control, window=None)[0] == "released"
    assert _class(values, control, window=0.3)[0] == "unseen"
    # an alarm up when the window opens is traced back to where it began
    cls, m = _class([0.1, 0.9, 0.9, 0.9, 0.9, 0.9], ".GGGGG", window=0.2)
    assert cls == "failed manoeuvre" and m["first"] == 1 and m["alarm_to_impact_s"] == pytest.approx(0.5)


def test_a_guardian_without_an_alarm_is_classified_by_who_was_in_control():
    for guardian in (Silent(), Scripted([None] * 6)):  # no hook, or a hook returning None
        log = _log(guardian, "..GG..")
        assert log.alarms == [None] * 6
        cls, m = classify(log.active, log.alarms, log.times, False, 1, None)
        assert cls == "released" and not m["signal"] and m["first"] == 2 and math.isnan(m["peak_before"])
    assert _class(None, "..GGGG", last_steps=1)[0] == "failed manoeuvre"
    assert _class(None, "......", last_steps=1)[0] == "unseen"
    assert _class(None, "....GG", last_steps=2)[0] == "unseen"


def test_onset_and_the_other_agents_lead():
    assert onset([False, True, True, False, True], 2, 5) == 1
    assert onset([False] * 4, 0, 4) is None
    log = _log(Silent(), "..GGG...")  # in control from 0.2 s
    assert versus_lead(log, 0.6, 0.3) == pytest.approx(0.4)
    assert math.isnan(versus_lead(log, 0.9, 0.05))


def test_classify_refuses_a_malformed_log():
    with pytest.raises(ValueError, match="at least one step"):
        classify([], [], [0.0], False, 1)


# ---------------------------------------------------------------- end to end, on stored runs


def _trimmed(tmp: Path, name: str, last: int, sql: tuple[str, ...] = ()) -> Path:
    """A results directory holding the shipped reference ``name`` with episodes ``0..last`` only."""
    out = Path(tempfile.mkdtemp(prefix=f"{name}-{last}-", dir=tmp))
    shutil.copyfile(REFERENCE / f"{name}.db", out / "results.db")
    con = sqlite3.connect(out / "results.db")
    con.execute("DELETE FROM episodes WHERE episode > ?", (last,))
    for q in sql:
        con.execute(q)
    con.commit()
    con.close()
    return out


@pytest.fixture(scope="module")
def dubins(tmp_path_factory) -> Path:
    """Dubins4D's reference episodes 0-17: lrmm collides in 6, 11 and 17 (doomed), cbf in 13 and 17."""
    return _trimmed(tmp_path_factory.mktemp("collisions"), "dubins4d", 17)


def _cli(capsys, *argv) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["collisions", *map(str, argv), "--no-progress"])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_stored_collisions_are_replayed_verified_and_classified(dubins, capsys):
    code, out, err = _cli(capsys, dubins, "--agent", "lrmm", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    got = {e["episode"]: e for e in doc["episodes"]}
    assert sorted(got) == [6, 11, 17]
    assert all(e["verified"] for e in got.values())
    assert got[17]["cls"] == "doomed" and got[17]["doomed"] is True
    assert got[6]["cls"] == got[11]["cls"] == "unseen"  # lrmm's risk rose within the last 3 steps
    assert all(e["signal"] for e in got.values())
    assert got[6]["threshold"] == pytest.approx(0.25)
    assert doc["collisions"] == 3 and doc["window_s"] == 3.0 and doc["last_steps"] == 3
    assert "replayed 3 episodes" in err


def test_versus_keeps_the_collisions_the_other_agent_avoids(dubins, capsys, tmp_path):
    table = tmp_path / "t.md"
    code, _, err = _cli(capsys, dubins, "--agent", "lrmm", "--versus", "cbf", "--table", table)
    assert code == 0, err
    text = table.read_text()
    assert "lrmm's collisions that cbf avoids" in text and "2 episodes (of its 3 collisions" in text
    assert "| 6 |" in text and "| 11 |" in text and "| 17 |" not in text
    assert "| unseen | 2 | 100% |" in text
    code, out, _ = _cli(capsys, dubins, "--agent", "lrmm", "--versus", "cbf", "--format", "csv")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].startswith("episode,seed,cls,") and len(lines) == 3
    assert all(",goal," in line for line in lines[1:])


def test_an_agent_without_an_alarm_is_classified_by_control_end_to_end(dubins, capsys):
    code, out, err = _cli(capsys, dubins, "--agent", "inactive", "--versus", "cbf", "--format", "json")
    assert code == 0, err
    eps = json.loads(out)["episodes"]
    assert len(eps) >= 5 and 13 not in {e["episode"] for e in eps}  # cbf collided in 13
    assert all(not e["signal"] and e["cls"] == "unseen" and e["alarm_to_impact_s"] is None for e in eps)


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--agent", "lrmmm"], "--agent lrmmm: no run of 'lrmmm'"),
        (["--agent", "lrmm", "--versus", "cbff"], "--versus cbff: no run of 'cbff'"),
        (["--agent", "lrmm", "--versus", "lrmm"], "--versus lrmm: the same agent"),
        (["--agent", "lrmm", "--last-steps", "-1"], "--last-steps -1"),
        (["--agent", "lrmm", "--window", "0"], "--window 0.0"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(dubins, capsys, argv, expected):
    code, out, err = _cli(capsys, dubins, *argv)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and expected in err


def test_no_collision_and_no_pair_are_one_line_and_exit_2(tmp_path, capsys):
    missing = tmp_path / "nothing"
    code, _, err = _cli(capsys, missing, "--agent", "lrmm")
    assert code == 2 and str(missing) in err and len(err.strip().splitlines()) == 1
    quiet = _trimmed(tmp_path, "dubins4d", 5)  # no collision in episodes 0-5 but inactive's
    code, _, err = _cli(capsys, quiet, "--agent", "lrmm")
    assert code == 2 and "--agent lrmm: none of the 6 episodes" in err and len(err.strip().splitlines()) == 1
    unpaired = _trimmed(tmp_path, "dubins4d", 17, ("DELETE FROM episodes WHERE agent = 'cbf' AND episode > 5",))
    code, _, err = _cli(capsys, unpaired, "--agent", "lrmm", "--versus", "cbf")
    assert code == 2 and "--versus cbf: its run" in err and "none of lrmm's 3 collision episodes" in err
    code, _, err = _cli(capsys, _trimmed(tmp_path, "dubins4d", 17, ("",)), "--agent", "hj", "--versus", "cbf")
    assert code == 2 and "--versus cbf: it avoided none of hj's 1 paired collisions" in err
