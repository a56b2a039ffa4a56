import os
import re
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import pytest
import tomllib

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS))
import gen  # noqa: E402

_TRAINS = pytest.mark.slow  # label, train and benchmark end to end: 7-10 s of CPU, 25-45 s on a busy machine


@pytest.mark.parametrize(
    "script, args",
    [
        ("third_party_guardian.py", []),
        ("braking_filter.py", []),
        ("new_system.py", []),
        pytest.param(
            "label_and_train.py",
            ["--configs", "6", "--samples", "16", "--branches", "8", "--epochs", "3"],
            marks=_TRAINS,
        ),
        pytest.param(
            "own_simulator.py", ["--configs", "4", "--samples", "32", "--epochs", "3", "--episodes", "4"], marks=_TRAINS
        ),
        # PPO-Lagrangian on info["cost"], and plain PPO; the script asserts its table's rows and counts
        pytest.param(
            "rl_guardian.py", ["--timesteps", "2048", "--episodes", "2", "--cost-limit", "0.1"], marks=_TRAINS
        ),
        pytest.param("rl_guardian.py", ["--timesteps", "2048", "--episodes", "4"], marks=_TRAINS),
    ],
)
def test_example_scripts_run(script, args, tmp_path):
    # TMPDIR: the scripts' scratch folders (and stable-baselines3's logger folder) land in the
    # test's own directory, which pytest prunes, not in the machine's /tmp
    env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(tmp_path))
    res = subprocess.run(
        [sys.executable, str(DOCS / "examples" / script), *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        env=env,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip()


def test_generated_pages_are_current():
    for rel, text in gen.pages().items():
        assert (DOCS / rel).read_text() == text, f"docs/{rel} is stale: run python docs/gen.py"


def test_generated_blocks_are_current():
    for rel in gen.BLOCKS:
        text = (DOCS / rel).read_text()
        assert gen.with_blocks(rel, text) == text, f"a generated block of docs/{rel} is stale: run python docs/gen.py"
    block = gen.lrmm_decisions_block()
    assert "`RatedDriver(margin=0.15, still=0.05, stay=True), Commit(steps=20), SafestCandidate(), Slide()`" in block


def _section(page: str, name: str) -> str:
    m = re.search(rf"## `{re.escape(name)}`\n\n```text\n(.*?)\n```", page, re.S)
    assert m, f"{name} is missing from docs/cli.md"
    return m.group(1)


def test_every_console_script_help_matches_the_reference(monkeypatch, capsys):
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    page = (DOCS / "cli.md").read_text()
    bindir = Path(sys.executable).parent
    env = dict(os.environ, COLUMNS="100")
    for name in scripts:
        exe = bindir / name
        assert exe.exists(), f"console script {name} is not installed next to {sys.executable}"
    # one installed script run as a user runs it; the rest in this process (a fresh interpreter
    # each costs a second of imports, and the text is the same)
    out = subprocess.run([str(bindir / "rmm-bench"), "--help"], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.rstrip() == _section(page, "rmm-bench"), "`rmm-bench --help` differs from docs/cli.md"
    monkeypatch.setenv("COLUMNS", "100")
    eps = {ep.name: ep for ep in entry_points(group="console_scripts") if ep.name in scripts}
    assert set(eps) == set(scripts), f"console scripts not installed: {set(scripts) - set(eps)}"
    calls = [(name, [name], ["--help"]) for name in scripts]
    calls += [("rmm-bench", [f"rmm-bench {sub}"], [sub, "--help"]) for sub in ("report", "sweep")]
    calls += [("rmm-envs", ["rmm-envs demo"], ["demo", "--help"])]
    for name, (section,), argv in calls:
        assert eps[name].value == scripts[name], (
            f"{name} is installed as {eps[name].value}, pyproject says {scripts[name]}"
        )
        monkeypatch.setattr(sys, "argv", [name, *argv])
        with pytest.raises(SystemExit) as stop:
            eps[name].load()(argv)
        assert stop.value.code in (0, None), f"`{section} --help` exited with {stop.value.code}"
        assert capsys.readouterr().out.rstrip() == _section(page, section), (
            f"`{section} --help` differs from docs/cli.md"
        )


def test_links_between_pages_resolve():
    """Every markdown link to a file names one that exists (the README's too, which is not part
    of the site; ``make docs`` checks the site's page links and anchors with -W)."""
    pages = list(DOCS.rglob("*.md")) + [ROOT / "README.md"]
    bad = []
    for page in pages:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
            if re.match(r"^[a-z]+://", target) or target.startswith("#"):
                continue
            path = (page.parent / target.split("#")[0]).resolve()
            if not path.exists():
                bad.append(f"{page.relative_to(ROOT)} -> {target}")
    assert not bad, bad


#: a fenced block that is not run says why on the line before it
NOT_RUN = re.compile(r"<!-- not-run: (.+?) -->\s*$")
SHELL = ("bash", "console")


def _shell_blocks():
    """Every ```bash and ```console block of the README and of docs/tutorials/, as (where, code,
    why not run or None)."""
    out = []
    for page in [ROOT / "README.md", *sorted((DOCS / "tutorials").glob("*.md"))]:
        text = page.read_text()
        for i, m in enumerate(re.finditer(r"^```(\w+)\n(.*?)\n```", text, re.S | re.M)):
            if m.group(1) not in SHELL:
                continue
            before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1]
            why = NOT_RUN.search(before)
            out.append((f"{page.relative_to(ROOT)}#{i}", m.group(1), m.group(2), why.group(1) if why else None))
    return out


SHELL_BLOCKS = _shell_blocks()


def _commands(kind: str, code: str) -> str:
    """The commands of a block: a console block's ``$ `` lines (the rest is output)."""
    if kind == "bash":
        return code
    return "\n".join(line[2:] for line in code.splitlines() if line.startswith("$ "))


def test_readme_commands_after_the_set_up_say_where_they_run():
    """After the two set-up commands (``make run``, ``make test``) nothing is on PATH: a command of
    the README runs from ``.venv/bin/`` (or is a make target)."""
    bare = []
    for where, kind, code, _ in SHELL_BLOCKS:
        if not where.startswith("README"):
            continue
        for line in _commands(kind, code).splitlines():
            word = line.strip().split(" ")[0] if line.strip() else ""
            if word and not word.startswith(("#", ".venv/bin/", "make", "source", "cd", "--", "git")):
                bare.append(f"{where}: {line.strip()}")
    assert not bare, bare


@pytest.mark.parametrize("where, kind, code, why", SHELL_BLOCKS, ids=[b[0] for b in SHELL_BLOCKS])
def test_shell_blocks_of_the_readme_and_tutorials_run(where, kind, code, why, tmp_path):
    """A reader runs the block from the repository's root after the two set-up commands: here in a
    scratch folder holding links to ``.venv`` and ``docs``; a tutorial's bare commands as after
    ``source .venv/bin/activate``, which the tutorial must say.  A block that takes minutes is
    marked ``<!-- not-run: REASON -->`` and skipped with that reason."""
    if why is not None:
        assert len(why.split()) >= 3, f"{where}: say why the block is not run"
        pytest.skip(f"not run: {why}")
    page = ROOT / where.split("#")[0]
    if not where.startswith("README"):
        assert "source .venv/bin/activate" in page.read_text(), f"{page.name}: say how to activate .venv"
    (tmp_path / ".venv").symlink_to(Path(sys.prefix))
    (tmp_path / "docs").symlink_to(DOCS)
    bindir = str(Path(sys.executable).parent)
    path = os.environ.get("PATH", "")
    if not where.startswith("README"):
        path = bindir + os.pathsep + path
    env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(tmp_path), PATH=path, COLUMNS="100")
    res = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", _commands(kind, code)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        env=env,
    )
    assert res.returncode == 0, f"{where} failed:\n{res.stdout[-1500:]}\n{res.stderr[-3000:]}"


def _python_snippets():
    """Every ```python block of the README and of docs/, as (where, code)."""
    out = []
    for page in [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]:
        for i, m in enumerate(re.finditer(r"```python\n(.*?)\n```", page.read_text(), re.S)):
            out.append((f"{page.relative_to(ROOT)}#{i}", m.group(1)))
    return out


SNIPPETS = _python_snippets()


def test_the_readme_and_getting_started_have_snippets():
    where = {w.split("#")[0] for w, _ in SNIPPETS}
    assert {"README.md", "docs/getting-started.md"} <= where


@pytest.mark.parametrize("where, code", SNIPPETS, ids=[w for w, _ in SNIPPETS])
def test_python_snippets_in_the_docs_run(where, code, tmp_path):
    """A reader pastes the snippet into a fresh interpreter: it must run, and an episode snippet
    must end with one of the three outcomes."""
    env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(tmp_path))  # scratch folders in the test's own directory
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env
    )
    assert res.returncode == 0, f"{where} failed:\n{res.stderr[-3000:]}"
    if "env.step(" in code and "outcome" in code:
        first = res.stdout.split()[0] if res.stdout.split() else ""
        assert first in ("goal", "collision", "timeout"), f"{where} printed {res.stdout[:200]!r}"


def test_the_dependencies_page_names_every_dependency_and_extra():
    """docs/getting-started.md "Dependencies": one line per runtime dependency and per extra of pyproject.toml."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    text = (DOCS / "getting-started.md").read_text()
    start = text.index("## Dependencies")
    end = text.find("\n## ", start + 3)
    section = text[start : end if end >= 0 else len(text)]
    lines = [ln for ln in section.splitlines() if ln.startswith("- ")]
    for dep in project["dependencies"]:
        name = re.split(r"[<>=!~\[ ;]", dep, maxsplit=1)[0]
        assert any(ln.startswith(f"- `{name}`") or f", `{name}`" in ln.split(":")[0] for ln in lines), name
    for extra in project["optional-dependencies"]:
        assert any(ln.startswith(f"- `{extra}`:") for ln in lines), extra
