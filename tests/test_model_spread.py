"""rmm-bench model-spread (rmm_bench.model_spread): each model gets the shipped guardian's decision (only the weights differ),
and bad input exits 2 before anything runs."""

from __future__ import annotations

import shutil

import numpy as np

from rmm_bench.cli import main
from rmm_bench.model_spread import _decided_copy
from rmm_guardians.lrmm.decision import decision_path, read_decision
from rmm_guardians.lrmm.guardian import LRMMGuardian
from rmm_guardians.lrmm.model import default_model_path


def test_a_model_gets_the_decision_of_the_env_s_shipped_guardian(tmp_path):
    # a model of one's own has no decision: the copy gets the shipped guardian's beside it
    src = tmp_path / "maze_seed1.npz"
    shutil.copy(default_model_path("Dubins3DMazeParallel-v0", variant="act"), src)
    assert not decision_path(src).exists()
    copy = _decided_copy(src, "Dubins3DMazeParallel-v0", tmp_path / "out")
    d = read_decision(decision_path(copy))
    shipped = LRMMGuardian(env_id="Dubins3DMazeParallel-v0")
    assert d.threshold == shipped.threshold == 0.7 and d.strategies == "Commit(steps=5)"
    assert copy.read_bytes() == src.read_bytes()  # the model file itself is a plain copy
    g = LRMMGuardian(model=copy, env_id="Dubins3DMazeParallel-v0")
    assert (g.threshold, g.strategies, g.inputs) == (shipped.threshold, shipped.strategies, "rays")
    for (w1, b1), (w2, b2) in zip(g.model.weights, shipped.model.weights, strict=True):  # the weights untouched
        np.testing.assert_array_equal(w1, w2)
        np.testing.assert_array_equal(b1, b2)
    assert not decision_path(src).exists()  # nothing is written beside the source file


def test_bad_input_exits_2_naming_it(tmp_path, capsys):
    assert main(["model-spread", "--env", "Dubins3DMazeParallel-v0", "--models", str(tmp_path / "a.npz")]) == 2
    assert "do not exist" in capsys.readouterr().err
    one = tmp_path / "one.npz"
    shutil.copy(default_model_path("Dubins3DMazeParallel-v0", variant="act"), one)
    assert main(["model-spread", "--env", "Dubins3DMazeParallel-v0", "--models", str(one)]) == 2
    assert "two or more" in capsys.readouterr().err
    assert (
        main(["model-spread", "--env", "Dubins3DMazeParallel-v0", "--models", f"{one},{one}", "--episodes", "0"]) == 2
    )
    assert "--episodes must be >= 1" in capsys.readouterr().err
