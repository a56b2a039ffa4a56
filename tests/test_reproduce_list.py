"""``rmm-bench reproduce --list`` from a wheel shows only the manifests whose commands a ``pip
install`` can run; from a clone it shows every manifest and marks the development scripts."""

from __future__ import annotations

from pathlib import Path

from rmm_bench.manifest import clone_only, in_clone, load_manifests
from rmm_bench.reproduce_command import list_manifests

ROOT = Path(__file__).resolve().parent.parent


def test_only_the_performance_and_map_manifests_need_a_clone():
    needing = {m.name: clone_only(m) for m in load_manifests() if clone_only(m)}
    assert set(needing) == {"performance", "map-env"}
    assert "benchmarks.perf_env" in needing["performance"]


def test_a_clone_is_told_from_a_wheel_by_the_scripts_beside_the_package(tmp_path):
    assert in_clone(ROOT)
    assert not in_clone(tmp_path)  # a wheel's site-packages: no benchmarks/ scripts
    (tmp_path / "benchmarks").mkdir()  # a user's own package of that name is no clone either
    assert not in_clone(tmp_path)


def test_a_wheel_lists_what_it_can_run_and_names_the_rest_in_one_line(capsys):
    manifests = load_manifests()
    assert list_manifests(manifests, clone=False) == 0
    lines = capsys.readouterr().out.splitlines()
    listed = [line.split(":")[0] for line in lines[:-1]]
    assert "performance" not in listed and "map-env" not in listed
    assert len(listed) == len(manifests) - 2
    assert not any("clone only" in line for line in lines[:-1])
    assert lines[-1].startswith("not listed: ") and "performance" in lines[-1] and "map-env" in lines[-1]


def test_a_clone_lists_every_manifest_marking_the_scripts(capsys):
    manifests = load_manifests()
    assert list_manifests(manifests, clone=True) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(manifests)
    perf = next(line for line in lines if line.startswith("performance:"))
    assert "clone only: benchmarks.perf_env" in perf
