"""Dataset generation (the paper's Algorithm 2) as ``rmm-datagen``.

For each procedurally generated obstacle configuration: sample valid states, observe them,
label them with the sampling-tree estimator.  Example (the paper's Dubins4D scale)::

    rmm-datagen --env Dubins4DGuarded-v0 --configs 274 --samples-per-config 128 --seed 0 --out data/d4

The output directory holds ``metadata.json``, ``shard-NNNNN.parquet`` files (rows grouped by
configuration) and, written last, ``manifest.json`` with every shard's SHA-256.  The same seed
gives identical data whatever the worker count or backend (``--backend local`` or ``ray``); a
rerun of the same command resumes, verifying and regenerating any damaged shard;
:func:`load_dataset` verifies every shard.

The files and the columns: :func:`generate`; why: docs/decisions/0007-datasets-and-models.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path

import pyarrow as pa
from tqdm import tqdm

from rmm_envs.defaults import DEFAULT_LABELLED_ENV
from rmm_envs.disturbances import parse_disturbances
from rmm_envs.os_errors import describe_os_error
from rmm_envs.pool import TaskLost, WorkersLost, run_local, run_ray
from rmm_envs.risk.dataset import (
    Dataset,
    load_dataset,
    prepare_folder,
    shard_path,
    shards_to_label,
    write_manifest,
    write_table,
)
from rmm_envs.risk.labelling import DatagenConfig, dataset_metadata, label_configs, labelled_env
from rmm_envs.risk.metrics import METRICS
from rmm_envs.user_modules import search_user_folders, user_folders

__all__ = ["DatagenConfig", "Dataset", "generate", "label_configs", "load_dataset", "main"]


def _shard_task(cfg_dict: dict, out: str | None, shard: int):
    """Worker entry: label one shard; write it (local) or return its bytes (ray)."""
    cfg = DatagenConfig(**cfg_dict)
    t0 = time.perf_counter()
    table = label_configs(cfg, cfg.shard_configs(shard))
    if out is not None:
        write_table(shard_path(Path(out), shard), table)
        return shard, table.num_rows, time.perf_counter() - t0, None
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema) as w:
        w.write_table(table)
    return shard, table.num_rows, time.perf_counter() - t0, sink.getvalue().to_pybytes()


def generate(
    cfg: DatagenConfig,
    out: str | os.PathLike,
    workers: int | None = None,
    backend: str = "local",
    ray_address: str | None = None,
    progress: bool = True,
) -> dict:
    """Generate (or finish) the dataset in ``out``; returns the manifest.

    Existing shards are kept only if they match the checksum recorded when they were written;
    the others are regenerated and listed in ``manifest["last_run"]["regenerated"]``.

    The folder ``out``:

    * ``metadata.json``: env id and arguments, estimator parameters, seed, sizes, package version;
    * ``shard-NNNNN.parquet``: the rows of a fixed block of configurations
      (``cfg.configs_per_shard``), grouped by configuration so that train/test can be split by
      configuration.  Columns ``config_id``, ``sample``, ``obs`` (float32 list), ``state``
      (float64 list), ``risk``, ``min_risk_ctrl`` (list), ``min_risk_ctrl_dur``, ``n_leaves``;
      with candidates also ``candidate_risk`` (a list, one action-conditioned label per candidate,
      :meth:`rmm_envs.risk.RiskEstimator.estimate_candidates`; drawn after the plain labels, so
      ``risk`` is the same with or without them);
    * ``shard-NNNNN.sha256`` (only while a run is unfinished): a shard's SHA-256, written right
      after the shard (``sha256sum -c`` format), folded into the manifest at the end;
    * ``manifest.json`` (written last): row count, per-shard SHA-256 and the dataset hash, built
      from the recorded checksums, never from what the files hold now.

    Configuration ``c`` draws everything from ``SeedSequence(seed, spawn_key=(c, ...))``.  Each
    shard is written to a temporary file and renamed into place.  A folder made with other
    parameters is refused rather than mixed.  Ray tasks return their rows to this process, which
    writes the shards, so no shared file system is needed.
    """
    cfg.validate()
    labelled_env(cfg)  # refuses an env that is not a LabelledEnv before anything is written
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(
            f"workers (--workers) must be an integer >= 1 (leave it out for one per core), got {workers!r}"
        )
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    prepare_folder(out, dataset_metadata(cfg))
    rows_of = {s: len(cfg.shard_configs(s)) * cfg.samples_per_config for s in range(cfg.n_shards)}
    todo, regenerated, verified = shards_to_label(out, rows_of)
    done_configs = cfg.configs - sum(len(cfg.shard_configs(s)) for s in todo)

    bar = tqdm(
        total=cfg.configs,
        initial=done_configs,
        unit="config",
        disable=not progress,
        desc=f"labelling {cfg.env_id}",
        dynamic_ncols=True,
    )
    t0 = time.perf_counter()
    new_rows = 0
    try:
        if todo:
            if backend == "local":
                new_rows = _run_local(cfg, out, todo, workers, bar)
            elif backend == "ray":
                new_rows = _run_ray(cfg, out, todo, ray_address, bar)
            else:
                raise ValueError(f"unknown backend {backend!r}; expected 'local' or 'ray'")
    except KeyboardInterrupt as e:
        bar.close()
        left = sum(1 for s in range(cfg.n_shards) if not shard_path(out, s).exists())
        print(
            f"\ninterrupted: {cfg.n_shards - left} of {cfg.n_shards} shards are saved in {out}; "
            "rerun the same command to finish",
            file=sys.stderr,
        )
        setattr(e, "told", True)  # noqa: B010 - main() adds no second line
        raise
    bar.close()
    elapsed = time.perf_counter() - t0

    last_run = {
        "new_rows": new_rows,
        "seconds": elapsed,
        "backend": backend,
        "labels_per_second": new_rows / elapsed if elapsed > 0 and new_rows else None,
        "regenerated": regenerated,
    }
    manifest = write_manifest(out, rows_of, verified, last_run)
    return manifest


def _shard_job(job):
    """Worker entry for :func:`rmm_envs.pool.run_local` / ``run_ray``: ``job`` is ``(config dict,
    out or None, shard, folders)``, ``folders`` those searched for the modules ``--env module:Id``
    and ``--failure module:callable`` name (the directory ``rmm-datagen`` ran in), after the
    installed packages."""
    *args, folders = job
    if folders:
        search_user_folders(folders)
    return _shard_task(*args)


# Stop after this many shards in a row lost their worker with none finishing: a cause that
# kills every worker (too little memory for one shard) then ends the run instead of starting
# a fresh worker for every remaining shard.
_MAX_LOST_IN_A_ROW = 3


def _lost_shards_error(lost: list, todo: list[int], out: Path, stopped: str | None = None) -> RuntimeError:
    what = "; ".join(f"shard {shard} ({cause})" for shard, cause in lost[:5]) + (
        f"; and {len(lost) - 5} more" if len(lost) > 5 else ""
    )
    head = f"{stopped}; " if stopped else ""
    return RuntimeError(
        f"{head}{len(lost)} of {len(todo)} shards to compute were lost: {what}. The finished shards are saved "
        f"in {out}; rerun the same command to compute the missing ones (fewer --workers if memory ran out)"
    )


def _collect(cfg: DatagenConfig, out: Path, todo: list[int], results, bar) -> int:
    """Count the rows of finished shards (writing those that came back as bytes, from Ray);
    a shard whose worker was lost is reported after the others finish."""
    rows = 0
    lost: list = []
    try:
        for res in results:
            if isinstance(res, TaskLost):
                lost.append((res.task[2], res.cause))
                continue
            shard, n, _, payload = res
            if payload is not None:
                write_table(shard_path(out, shard), pa.ipc.open_stream(payload).read_all())
            rows += n
            bar.update(len(cfg.shard_configs(shard)))
    except WorkersLost as e:
        raise _lost_shards_error(lost, todo, out, str(e)) from None
    if lost:
        raise _lost_shards_error(lost, todo, out)
    return rows


def _run_local(cfg: DatagenConfig, out: Path, todo: list[int], workers: int | None, bar) -> int:
    """Label the ``todo`` shards on local processes; a shard whose worker dies is reported, the rest finish."""
    if workers is None:
        workers = os.cpu_count() or 1  # generate() has refused anything but an integer >= 1
    jobs = [(asdict(cfg), str(out), s, (os.getcwd(),)) for s in todo]
    return _collect(cfg, out, todo, run_local(_shard_job, jobs, workers, max_lost_in_a_row=_MAX_LOST_IN_A_ROW), bar)


def _run_ray(cfg: DatagenConfig, out: Path, todo: list[int], address: str | None, bar) -> int:
    """Label the ``todo`` shards as Ray tasks and write them here; a shard Ray loses is reported."""
    jobs = [(asdict(cfg), None, s, (os.getcwd(),)) for s in todo]
    return _collect(cfg, out, todo, run_ray(_shard_job, jobs, address, max_lost_in_a_row=_MAX_LOST_IN_A_ROW), bar)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-datagen",
        description="Generate a risk-labelled dataset (Algorithm 2): obstacle configurations, "
        "valid states, their observations and sampling-tree risk labels, written as Parquet shards. "
        "Rerun the same command to resume an interrupted run.",
    )
    p.add_argument(
        "--env",
        default=DEFAULT_LABELLED_ENV,
        help="environment id, or module:Id to import the module that registers it first "
        "(from the current directory first) (default: %(default)s)",
    )
    p.add_argument("--configs", type=int, default=274, help="number of obstacle configurations (default: %(default)s)")
    p.add_argument(
        "--samples-per-config", type=int, default=128, help="labelled states per configuration (default: %(default)s)"
    )
    p.add_argument("--seed", type=int, default=0, help="master seed (default: %(default)s)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--branches", type=int, default=32, help="tree branching factor n (default: %(default)s)")
    p.add_argument("--depth", type=int, default=2, help="tree depth m (default: %(default)s)")
    p.add_argument(
        "--horizon",
        type=float,
        default=None,
        help="seconds per tree level t (default: 2 for the package's envs, the risk adapter's own for "
        "an adapted env such as CartPole-v1, see rmm_envs.adapters)",
    )
    p.add_argument(
        "--failure",
        default=None,
        help="'module:callable', failure(states) -> (N,) bool, for an env served by a risk adapter "
        "(required for Pendulum-v1 and for a MuJoCo env with no failure test of its own, such as Walker2d-v5; "
        "added to the adapter's own test elsewhere)",
    )
    p.add_argument("--n-steps", type=int, default=8, help="path points per branch (default: %(default)s)")
    p.add_argument(
        "--metric", default="expected", choices=list(METRICS), help="coherent risk metric (default: %(default)s)"
    )
    p.add_argument("--alpha", type=float, default=None, help="CVaR level in (0, 1) (with --metric cvar)")
    p.add_argument(
        "--leaf",
        default="zero",
        choices=["zero", "heuristic"],
        help="leaf value: 0 (Algorithm 1) or the system's heuristic (default: %(default)s)",
    )
    p.add_argument(
        "--env-opt",
        action="append",
        default=[],
        metavar="KEY=JSON",
        help="an argument of the env's constructor, its value as JSON (a string in quotes), e.g. "
        "maze_kind='\"mixed\"'; repeatable",
    )
    p.add_argument("--env-kwargs", default=None, help=argparse.SUPPRESS)  # refused in _main: --env-opt replaced it
    help_disturb = "sensor noise on the observations (labels: the true risk), e.g. obs-noise.rays=0.2; repeatable"
    p.add_argument("--disturb", action="append", default=[], metavar="KIND=LEVEL", help=help_disturb)
    p.add_argument(
        "--candidates",
        default=None,
        help="also label the risk of holding each of these controls for --candidate-hold s, then the tree, "
        "as JSON, e.g. '[[-0.25, -0.5], [0.25, -0.5]]' (default: none)",
    )
    p.add_argument(
        "--candidate-hold", type=float, default=1.0, help="seconds each candidate is held (default: %(default)s)"
    )
    p.add_argument(
        "--configs-per-shard", type=int, default=8, help="configurations per output shard (default: %(default)s)"
    )
    p.add_argument("--workers", type=int, default=None, help="worker processes, >= 1 (default: the core count)")
    p.add_argument(
        "--backend", default="local", choices=["local", "ray"], help="where the work runs (default: %(default)s)"
    )
    p.add_argument("--ray-address", default=None, help="Ray cluster address (with --backend ray; default: a local Ray)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)

    # --env module:Id and --failure module:callable are found here, after the installed packages
    # (never in their place: a tqdm.py here is not imported), in this process and every worker
    try:
        with user_folders([os.getcwd()]):
            return _main(args)
    except KeyboardInterrupt as e:  # one line, no traceback (generate() says what it saved)
        if not getattr(e, "told", False):
            print("rmm-datagen: interrupted (Ctrl-C); rerun the same command to finish", file=sys.stderr)
        return 130


def env_options(items: list[str]) -> dict:
    """``--env-opt KEY=JSON`` values as the env's keyword arguments; ValueError, in one line naming
    the item, for one without ``=``, a value that is not JSON or a key given twice (an argument the
    env does not take is named when the env is built)."""
    opts: dict = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--env-opt {item!r}: expected KEY=JSON, e.g. maze_kind='\"mixed\"'")
        if key in opts:
            raise ValueError(f"--env-opt {item!r}: {key} is given twice; give each argument once")
        try:
            opts[key] = json.loads(value)
        except json.JSONDecodeError:
            raise ValueError(f"--env-opt {item!r}: the value {value!r} is not JSON (a string needs quotes)") from None
    return opts


def _main(args) -> int:
    if args.env_kwargs is not None:
        print(
            "rmm-datagen: error: --env-kwargs is no longer accepted; use --env-opt KEY=JSON, once per argument",
            file=sys.stderr,
        )
        return 2
    try:
        env_kwargs = env_options(args.env_opt)
        if args.disturb and "disturbances" in env_kwargs:
            raise ValueError("give disturbances with --disturb or with --env-opt disturbances=..., not both")
        if args.disturb:
            env_kwargs["disturbances"] = sorted(str(d) for d in parse_disturbances(args.disturb))
    except ValueError as e:
        print(f"rmm-datagen: error: {e}", file=sys.stderr)
        return 2
    try:
        candidates = None if args.candidates is None else json.loads(args.candidates)
        if candidates is not None and not (
            isinstance(candidates, list) and all(isinstance(c, list) for c in candidates)
        ):
            raise ValueError
    except ValueError:
        print(
            f"rmm-datagen: error: --candidates must be a JSON list of controls, got {args.candidates!r}",
            file=sys.stderr,
        )
        return 2
    cfg = DatagenConfig(
        env_id=args.env,
        configs=args.configs,
        samples_per_config=args.samples_per_config,
        seed=args.seed,
        branches=args.branches,
        depth=args.depth,
        horizon=args.horizon,
        n_steps=args.n_steps,
        metric=args.metric,
        alpha=args.alpha,
        leaf=args.leaf,
        configs_per_shard=args.configs_per_shard,
        env_kwargs=env_kwargs,
        candidates=candidates,
        candidate_hold=args.candidate_hold,
        failure=args.failure,
    )
    try:
        manifest = generate(
            cfg,
            args.out,
            workers=args.workers,
            backend=args.backend,
            ray_address=args.ray_address,
            progress=not args.no_progress,
        )
    except (ValueError, TypeError, RuntimeError, FileNotFoundError) as e:  # TypeError: an env that is not a LabelledEnv
        print(f"rmm-datagen: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # an --out that is a file or not writable (2), a full disk in a worker or here (1)
        message, status = describe_os_error(e, args.out)
        print(f"rmm-datagen: error: {message}", file=sys.stderr)
        return status
    run = manifest["last_run"]
    rate = f", {run['labels_per_second']:.0f} labels/s" if run["labels_per_second"] else ""
    print(
        f"{manifest['n_rows']} labelled samples in {args.out} ({manifest['n_shards']} shards); "
        f"this run: {run['new_rows']} new in {run['seconds']:.1f} s{rate}; dataset sha256 {manifest['dataset_sha256'][:16]}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
