"""The tutorial is the test (issue 50, item 6): docs/tutorials/own-simulator.md, "Your own
simulator, end to end", run exactly as written, from a research directory.

The page's ``<!-- file: PATH -->`` blocks are written into a temporary folder (``pyproject.toml``
and the package ``cart_wall/``), and its ``<!-- not-run: chain step ... -->`` bash blocks are run
there in order, as a user runs them after ``source .venv/bin/activate``: the installed commands
on ``PATH``, nothing of this repository on ``sys.path`` or in the current folder.  The folder also
holds packages named ``benchmarks``, ``guardians``, ``tests`` and ``rmm`` whose ``__init__.py``
raises ``ImportError``, and it is on ``PYTHONPATH``, so a command that imported anything of this
project by one of those names (a clone-only script, a module of the checkout) fails.

Registration by entry point without pip: the tutorial's ``pip install -e .`` is the one block not
run.  In its place the test writes ``cart_wall-0.1.dist-info/`` (``METADATA`` and
``entry_points.txt``, the latter from the page's ``[project.entry-points]`` tables) into the folder
on ``PYTHONPATH``, exactly as an installed distribution appears to ``importlib.metadata``; with the
package itself on ``PYTHONPATH`` that is what an editable install amounts to.

Sizes are substituted only through the documented variables of the chain's first block
(``CONFIGS``, ``SAMPLES``, ``EPOCHS``, ``EPISODES``, ``WORKERS``): the default suite runs the chain
tiny; ``-m slow`` runs it at the page's own sizes and checks the results the page quotes.
"""

from __future__ import annotations

import csv
import json
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest
import tomllib

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "tutorials" / "own-simulator.md"
BIN = Path(sys.executable).parent

FILE_BLOCK = re.compile(r"^<!-- file: (\S+) -->\n```(\w+)\n(.*?)\n```$", re.S | re.M)
CHAIN_BLOCK = re.compile(r"^<!-- not-run: chain step[^>]*-->\n```bash\n(.*?)\n```$", re.S | re.M)
#: the variables the page documents as the chain's sizes: the only thing the test changes
SIZES = ("CONFIGS", "SAMPLES", "EPOCHS", "EPISODES", "WORKERS")
#: the smallest chain that exercises every step (rmm-train splits by configuration: at least 3)
TINY = {"CONFIGS": "3", "SAMPLES": "16", "EPOCHS": "5", "EPISODES": "4", "WORKERS": "1"}
DECOYS = ("benchmarks", "guardians", "tests", "rmm")


def _page() -> str:
    return PAGE.read_text()


def files() -> dict[str, str]:
    """The folder the page writes: path -> text."""
    return {path: code + "\n" for path, _, code in FILE_BLOCK.findall(_page())}


def chain() -> tuple[dict[str, str], list[str]]:
    """The page's sizes (its first chain block) and the chain's other blocks, in order."""
    blocks = CHAIN_BLOCK.findall(_page())
    assert blocks, "the page has no <!-- not-run: chain step ... --> bash blocks"
    sizes = {}
    for word in shlex.split(blocks[0], comments=True):
        name, eq, value = word.partition("=")
        assert eq and name in SIZES, f"the chain's first block sets only the sizes {SIZES}: {word!r}"
        sizes[name] = value
    assert set(sizes) == set(SIZES), f"the sizes block sets {sorted(sizes)}, the test knows {SIZES}"
    return sizes, blocks[1:]


def _dist_info(folder: Path) -> Path:
    """``NAME-VERSION.dist-info`` of the page's pyproject.toml: what ``pip install -e .`` leaves
    for importlib.metadata (the package itself is found on PYTHONPATH)."""
    project = tomllib.loads((folder / "pyproject.toml").read_text())["project"]
    info = folder / f"{project['name'].replace('-', '_')}-{project['version']}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n")
    groups = project.get("entry-points", {})
    (info / "entry_points.txt").write_text(
        "".join(f"[{g}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()) + "\n" for g, eps in groups.items())
    )
    return info


def research_dir(tmp_path: Path) -> Path:
    """A user's folder: the page's files, the stand-in for their installation, and the decoys."""
    folder = tmp_path / "research"
    for rel, text in files().items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_text(text)
    _dist_info(folder)
    for name in DECOYS:
        (folder / name).mkdir()
        (folder / name / "__init__.py").write_text(
            f"raise ImportError('{name} here is the research folder own package: rmm must not import it')\n"
        )
    return folder


def run_chain(folder: Path, sizes: dict[str, str]) -> tuple[list[str], float]:
    """Run the chain's blocks in ``folder`` with ``sizes``; each block's stdout, and the seconds."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSAFEPATH", "PYTHONHOME")}
    env.update(sizes, PYTHONPATH=str(folder), PATH=str(BIN) + os.pathsep + env.get("PATH", ""))
    env.update(MPLBACKEND="Agg", TMPDIR=str(folder.parent), COLUMNS="100")
    outs = []
    start = time.perf_counter()
    for code in chain()[1]:
        res = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", code], cwd=folder, env=env, capture_output=True, text=True, timeout=900
        )
        assert res.returncode == 0, f"the tutorial's block failed:\n{code}\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"
        outs.append(res.stdout)
    return outs, time.perf_counter() - start


def _step(outs: list[str], command: str) -> str:
    blocks = chain()[1]
    hits = [i for i, code in enumerate(blocks) if command in code]
    assert hits, f"no block of the chain runs {command!r}"
    return outs[hits[0]]


def check_outputs(folder: Path, outs: list[str], sizes: dict[str, str]) -> dict[str, dict]:
    """The chain's outputs, each where the page says it is; Table I's rows by agent."""
    n = int(sizes["EPISODES"])
    m = re.search(r"(\d+) of (\d+) checks passed", _step(outs, "rmm-bench check-system"))
    assert m and m.group(1) == m.group(2), _step(outs, "rmm-bench check-system")
    manifest = json.loads((folder / "data" / "cart_wall" / "manifest.json").read_text())
    assert manifest["n_rows"] == int(sizes["CONFIGS"]) * int(sizes["SAMPLES"])
    meta = json.loads((folder / "data" / "cart_wall" / "metadata.json").read_text())
    assert meta["env_id"] == "CartWallGuarded-v0"
    assert (folder / "cart_wall.npz").is_file()
    decision = tomllib.loads((folder / "cart_wall.decision.toml").read_text())
    assert 0.0 <= decision["threshold"] <= 1.0 and "rmm-bench tune" in decision["chosen_by"]["command"]
    assert "wrote cart_wall.decision.toml" in _step(outs, "rmm-bench tune")
    with open(folder / "runs" / "table1" / "table_I.csv") as f:
        rows = {r["agent"]: r for r in csv.DictReader(f)}
    assert list(rows) == ["inactive", "lrmm"] and all(r["episodes"] == str(n) for r in rows.values()), rows
    replay = _step(outs, "rmm-bench replay")
    assert "episode 2: verified" in replay, replay
    from PIL import Image

    with Image.open(folder / "lrmm-2.gif") as gif:
        assert gif.n_frames > 2 and gif.size[1] > 0
        gif.seek(gif.n_frames - 1)  # every frame decodes
    compare = _step(outs, "rmm-bench compare")
    for outcome in ("goal", "collision", "timeout"):
        assert f"| inactive | lrmm | {outcome} | {n} |" in compare, compare
    return rows


def test_the_page_writes_one_folder_registered_by_entry_point_and_runs_the_seven_steps():
    written = files()
    assert set(written) == {
        "pyproject.toml",
        *(f"cart_wall/{m}.py" for m in ("__init__", "simulator", "env", "system")),
    }
    project = tomllib.loads(written["pyproject.toml"])["project"]
    assert project["entry-points"]["rmm_envs.systems"] == {"CartWall": "cart_wall.system:spec"}
    assert "import rmm" not in written["cart_wall/simulator.py"]  # the simulator knows nothing of this project
    sizes, blocks = chain()
    commands = [ln for code in blocks for ln in code.splitlines() if ln.strip()]
    steps = ["rmm-bench check-system", "rmm-datagen", "rmm-train", "rmm-bench tune", "rmm-bench --env"]
    steps += ["rmm-bench replay", "rmm-bench compare"]
    assert [next(s for s in steps if ln.startswith(s)) for ln in commands] == steps, commands
    for name in SIZES:  # every size is used, and only through its variable
        assert f"${name}" in "\n".join(blocks), name
    assert "--agent inactive,lrmm" in commands[4] and "--video lrmm-2.gif" in commands[5]


@pytest.mark.heavy(seconds=60)
def test_the_tutorials_chain_runs_from_a_research_folder(tmp_path):
    folder = research_dir(tmp_path)
    outs, seconds = run_chain(folder, TINY)
    check_outputs(folder, outs, TINY)
    print(f"the tutorial's chain, tiny: {seconds:.0f} s")


def _quoted_rates() -> dict[str, tuple[str, str]]:
    """The Table I rows the page quotes for the chain: agent -> (success, collision)."""
    text = _page()
    start = text.index("## Your own simulator, end to end")
    section = text[start : text.index("\n## ", start)]
    out = {}
    for line in re.findall(r"^\| (?:inactive|lrmm) \| .*$", section, re.M):
        cells = [c.strip() for c in line.strip("|").split("|")]
        out[cells[0]] = (cells[6].split()[0], cells[7].split()[0])
    assert set(out) == {"inactive", "lrmm"}, "the page quotes Table I's rows of inactive and lrmm"
    return out


@pytest.mark.slow
def test_the_tutorials_chain_at_its_own_sizes_makes_the_table_it_quotes(tmp_path):
    folder = research_dir(tmp_path)
    sizes = chain()[0]
    outs, seconds = run_chain(folder, sizes)
    rows = check_outputs(folder, outs, sizes)
    made = {a: (f"{float(r['success_mean']):.1f}", f"{float(r['collision_mean']):.1f}") for a, r in rows.items()}
    assert made == _quoted_rates()
    assert float(rows["lrmm"]["collision_mean"]) < float(rows["inactive"]["collision_mean"])
    print(f"the tutorial's chain at its own sizes: {seconds:.0f} s")
