"""Old import paths of moved modules keep working, with a DeprecationWarning naming the new one."""

from __future__ import annotations

import importlib
import sys

import pytest


@pytest.mark.parametrize("old, new, name", [("rmm_envs.driver", "rmm_envs.drivers.dubins4d", "CLFDriver"),
                                            ("rmm_envs.maze_driver", "rmm_envs.drivers.maze", "cell_path"),
                                            ("rmm_envs.quadrotor_pilot", "rmm_envs.drivers.quadrotor", "WaypointPilot"),
                                            ("rmm_envs.parallel", "rmm_envs.pool", "run_local")])
def test_a_moved_module_warns_and_gives_the_new_module_s_public_names(monkeypatch, old, new, name):
    monkeypatch.delitem(sys.modules, old, raising=False)  # import it afresh: the warning comes with the import
    with pytest.warns(DeprecationWarning, match=f"module {old} moved to {new}; import it from there"):
        shim = importlib.import_module(old)
    target = importlib.import_module(new)
    assert shim.__all__ == target.__all__ and name in shim.__all__
    assert all(getattr(shim, n) is getattr(target, n) for n in target.__all__)
