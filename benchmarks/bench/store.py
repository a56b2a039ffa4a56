"""The results store: an embedded SQLite database (``results.db``).

Tables:

* ``runs``: one row per (agent, configuration): ``run_key`` (a hash of everything that
  determines an episode's result except the episode index), the agent, the full
  configuration and provenance (package version, git revision, command line, Python).
* ``episodes``: one row per finished episode, keyed by ``(run_key, episode)``, committed as
  soon as it ends (WAL journal), so killing a run loses at most the episodes in flight and a
  rerun skips what is stored.
* ``invocations``: each ``rmm-bench`` command: its arguments, run keys and episode count, so
  ``rmm-bench report DIR`` can rebuild exactly that command's table.
"""

from __future__ import annotations

import json
import sqlite3
import time
from pathlib import Path

__all__ = ["EPISODE_FIELDS", "ResultsStore"]

EPISODE_FIELDS = {
    "run_key": "TEXT NOT NULL",
    "episode": "INTEGER NOT NULL",
    "agent": "TEXT NOT NULL",
    "seed": "INTEGER NOT NULL",
    "outcome": "TEXT NOT NULL",  # goal / collision / timeout / error
    "steps": "INTEGER",
    "active_steps": "INTEGER",
    "sim_time": "REAL",
    "active_sim_time": "REAL",
    "compute_time": "REAL",  # the env clock's total agent time, s
    "avg_compute_time": "REAL",  # per step, s (Table I's policy compute time)
    "decision_mean": "REAL",  # guardian.act() wall time per call, s
    "decision_std": "REAL",
    "decision_max": "REAL",
    "precompute_time": "REAL",  # guardian.reset(), s (e.g. an HJ solve)
    "final_speed": "REAL",
    "cum_reward": "REAL",
    "qp_fallbacks": "INTEGER",
    "nan_states": "INTEGER",
    "guardian_stats": "TEXT",
    "error": "TEXT",
    "wall_time": "REAL",
    "finished": "REAL",
}


class ResultsStore:
    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.db = sqlite3.connect(str(self.path), timeout=30)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=NORMAL")
        cols = ", ".join(f"{k} {v}" for k, v in EPISODE_FIELDS.items())
        self.db.executescript(f"""
            CREATE TABLE IF NOT EXISTS runs (run_key TEXT PRIMARY KEY, agent TEXT NOT NULL, created REAL,
                config TEXT NOT NULL, provenance TEXT NOT NULL);
            CREATE TABLE IF NOT EXISTS episodes ({cols}, PRIMARY KEY (run_key, episode));
            CREATE TABLE IF NOT EXISTS invocations (id INTEGER PRIMARY KEY AUTOINCREMENT, created REAL,
                kind TEXT, args TEXT, run_keys TEXT, episodes INTEGER, status TEXT);
        """)
        self.db.commit()

    def close(self) -> None:
        self.db.close()

    # runs
    def ensure_run(self, run_key: str, agent: str, config: dict, provenance: dict) -> None:
        self.db.execute("INSERT OR IGNORE INTO runs VALUES (?, ?, ?, ?, ?)",
                        (run_key, agent, time.time(), json.dumps(config, sort_keys=True), json.dumps(provenance, sort_keys=True)))
        self.db.commit()

    def run_config(self, run_key: str) -> dict:
        row = self.db.execute("SELECT config, provenance, agent FROM runs WHERE run_key = ?", (run_key,)).fetchone()
        if row is None:
            raise KeyError(run_key)
        return {"config": json.loads(row[0]), "provenance": json.loads(row[1]), "agent": row[2]}

    # episodes
    def done_episodes(self, run_key: str) -> set[int]:
        return {r[0] for r in self.db.execute("SELECT episode FROM episodes WHERE run_key = ?", (run_key,))}

    def add_episode(self, row: dict) -> None:
        keys = list(EPISODE_FIELDS)
        vals = [row.get(k) for k in keys]
        self.db.execute(f"INSERT OR IGNORE INTO episodes ({', '.join(keys)}) VALUES ({', '.join('?' * len(keys))})", vals)
        self.db.commit()

    def episodes(self, run_key: str, n: int | None = None) -> list[dict]:
        q = "SELECT * FROM episodes WHERE run_key = ?" + (" AND episode < ?" if n is not None else "") + " ORDER BY episode"
        cur = self.db.execute(q, (run_key, n) if n is not None else (run_key,))
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r)) for r in cur.fetchall()]

    # invocations
    def add_invocation(self, kind: str, args: dict, run_keys: dict, episodes: int) -> int:
        cur = self.db.execute("INSERT INTO invocations (created, kind, args, run_keys, episodes, status) VALUES (?, ?, ?, ?, ?, ?)",
                              (time.time(), kind, json.dumps(args, sort_keys=True), json.dumps(run_keys), episodes, "running"))
        self.db.commit()
        return int(cur.lastrowid)

    def finish_invocation(self, inv_id: int, status: str = "done") -> None:
        self.db.execute("UPDATE invocations SET status = ? WHERE id = ?", (status, inv_id))
        self.db.commit()

    def invocation(self, inv_id: int | None = None, kind: str | None = None) -> dict:
        q = "SELECT id, created, kind, args, run_keys, episodes, status FROM invocations"
        params: tuple = ()
        if inv_id is not None:
            q += " WHERE id = ?"
            params = (inv_id,)
        elif kind is not None:
            q += " WHERE kind = ?"
            params = (kind,)
        q += " ORDER BY id DESC LIMIT 1"
        row = self.db.execute(q, params).fetchone()
        if row is None:
            raise LookupError(f"no {'invocation ' + str(inv_id) if inv_id else (kind or 'benchmark') + ' run'} recorded in {self.path}")
        return {"id": row[0], "created": row[1], "kind": row[2], "args": json.loads(row[3]),
                "run_keys": json.loads(row[4]), "episodes": row[5], "status": row[6]}
