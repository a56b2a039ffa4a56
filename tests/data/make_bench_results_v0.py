"""How ``bench_results_v0.db`` and ``bench_results_v0_table.md`` were made (kept for the record).

They pin the store's format as written before the benchmark configuration became typed
(commit 9f15a24, where ``rmm-bench`` passed dicts): ``tests/test_bench_config.py`` checks
that ``report`` rebuilds the same table from it and that ``--resume`` finds every episode
done.  To remake them, run this with that commit's code on the path (``git archive 9f15a24``
into a folder, then ``PYTHONPATH=that-folder python tests/data/make_bench_results_v0.py``
from an empty directory); machine-specific fields are replaced by fixed strings.  The table's two
headers were then edited to the envs' current ids, as ``report`` names a renamed env today.
"""

import json
import shutil
import sqlite3
import subprocess
import sys

COMMON = ["--clock", "fixed:1", "--workers", "1", "--out", "olddb", "--no-progress"]
subprocess.run(
    [sys.executable, "-m", "rmm_bench.cli", "--agent", "inactive,brakes", "--episodes", "3", *COMMON], check=True
)
subprocess.run(
    [
        sys.executable,
        "-m",
        "rmm_bench.cli",
        "--agent",
        "random",
        "--agent-opt",
        "random.p_active=0.5",
        "--env",
        "Dubins4DCircles-v0",
        "--episodes",
        "2",
        *COMMON,
    ],
    check=True,
)
con = sqlite3.connect("olddb/results.db")
con.execute("UPDATE invocations SET host = 'recorded-host', pid = 1")
for key, prov in con.execute("SELECT run_key, provenance FROM runs").fetchall():
    p = json.loads(prov) | {"platform": "recorded-platform", "git_revision": "9f15a24"}
    con.execute("UPDATE runs SET provenance = ? WHERE run_key = ?", (json.dumps(p, sort_keys=True), key))
con.commit()
con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
con.execute("PRAGMA journal_mode=DELETE")
con.execute("VACUUM")
con.close()
shutil.copy("olddb/results.db", "bench_results_v0.db")
subprocess.run(
    [sys.executable, "-m", "rmm_bench.cli", "report", "olddb", "--invocation", "1", "--invocation", "2"],
    check=True,
    stdout=subprocess.DEVNULL,
)
shutil.copy("olddb/table_I.md", "bench_results_v0_table.md")
