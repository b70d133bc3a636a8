"""`gecgen fleet MANIFEST.csv -o DIR [--scheduler ADDRESS] [--workers N]`: many robots calibrated at once.

A manufacturer calibrates every robot leaving the line; a plant re-checks its arms every month. The
manifest (CSV, one robot a row; paths relative to the manifest's folder) names each robot's files:

| column | |
|---|---|
| `name` | the robot's name in the results: its folder under DIR (letters, digits, `-`, `_`, `.`) |
| `robot`, `train` | the robot file and its training measurements (required) |
| `val` / `holdout` | validation measurements, or the share of `train` to hold out (optional) |
| `errors` | the error model among the candidates (optional) |
| `models` | calibrate's candidates, separated by spaces or `;` (optional; default all) |

Each row is `gecgen calibrate ROBOT TRAIN [--val VAL | --holdout F] [--errors E] -o DIR/NAME`, run
by the same entry point as the command itself, so its folder and figures are those of running it
alone. The rows are tasks on Dask (`dask.distributed`): a local cluster of `--workers` processes by
default, or the scheduler at `--scheduler` (a real cluster: every worker must see the files at the
same paths). A robot that fails is reported with its one-line reason and the others go on; the
command then exits 1 naming them. DIR gets `fleet.json` and `fleet.csv`, one row per robot. While
its tasks run DIR holds `fleet.incomplete` (and no summary of an earlier run): a run that is
interrupted or killed then leaves the folder marked so. A second fleet into DIR while one runs is
refused. Python: `calibrate_fleet(manifest, out)`.
"""
from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import logging
import re
import signal
import sys
import time
from pathlib import Path

from gecgen.cli.common import MAX_SEED, number, progress_status, say, whole
from gecgen.model.files import output_lock, write_atomically
from gecgen.model.measurements import write_csv
from gecgen.model.table import read_table
from gecgen.model.validation import ModelError, excerpt, require

COLUMNS = ("name", "robot", "train", "val", "holdout", "errors", "models")
#: a robot's name becomes a folder: no separators, nothing hidden
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
#: a scheduler's address as Dask takes it: protocol://host:port, or host:port
ADDRESS = re.compile(r"^([a-z]+://)?[^\s:/]+(:\d+)?$")
#: what the fleet itself writes into DIR beside the robots' folders: no robot may be named so
SUMMARY, TABLE, MARK = "fleet.json", "fleet.csv", "fleet.incomplete"


def add_parser(command):
    """Register `fleet` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("fleet", run)
    p.add_argument("manifest", help="CSV: name, robot, train[, val | holdout][, errors][, models], one robot a row")
    p.add_argument("-o", "--output", required=True,
                   help="folder: one calibrate folder per robot, fleet.json, fleet.csv")
    p.add_argument("--scheduler", help="address of a running Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=whole(1, 256), default=2,
                   help="processes of the local cluster (default %(default)s)")
    p.add_argument("--seed", type=whole(0, MAX_SEED), default=0,
                   help="calibrate's --seed for every robot (default %(default)s)")
    p.add_argument("--timeout", type=number(0, above=True), default=None,
                   help="seconds to wait for the connection to --scheduler (default: Dask's)")


def read_manifest(path) -> list[dict]:
    """The manifest's robots: {name, robot, train, val, holdout, errors, models} (paths resolved against the
    manifest's folder; absent optional cells None). Refuses a missing required column, an empty or
    repeated name, a name that is not a plain folder name, and a row giving both val and holdout."""
    table = read_table(path, "fleet manifest", "name, robot, train", text=COLUMNS)
    where, folder = table.where, Path(path).resolve().parent
    for col in ("name", "robot", "train"):
        require(col in table.header, f"{where}: row 1: missing column '{col}' (needed: name, robot, train; optional: "
                                     f"val or holdout, errors, models)")
    unknown = [h for h in table.header if h not in COLUMNS]
    require(not unknown, f"{where}: row 1: unknown column {excerpt(unknown[0]) if unknown else ''}; the columns are "
                         f"{', '.join(COLUMNS)}")
    cells = {c: [v.strip() for v in table.cells(c)] if c in table.header else [""] * len(table) for c in COLUMNS}
    robots, seen = [], {}
    for r in range(len(table)):
        row = {c: cells[c][r] or None for c in COLUMNS}
        line = r + 2
        require(row["name"] and NAME.match(row["name"]),
                f"{where}: row {line}, column 'name': {excerpt(row['name'] or '')} is no folder name; use letters, "
                f"digits, '-', '_' and '.'")
        require(row["name"] not in seen,
                f"{where}: row {line}: name {row['name']} is also row {seen.get(row['name'])}'s; give each robot its "
                f"own name (its results folder)")
        require(row["name"].lower() not in (SUMMARY, TABLE, MARK),
                f"{where}: row {line}, column 'name': {row['name']} is a file the fleet writes beside the robots' "
                f"folders ({SUMMARY}, {TABLE}, {MARK}); name the robot otherwise")
        seen[row["name"]] = line
        require(row["robot"] and row["train"], f"{where}: row {line}: give the robot file and its training data")
        require(not (row["val"] and row["holdout"]), f"{where}: row {line}: val and holdout both given; one of them")
        for c in ("robot", "train", "val", "errors"):
            if row[c]:
                row[c] = str(folder / row[c])
        robots.append(row)
    require(robots, f"{where}: no robots; one row per robot")
    return robots


def calibrate_one(row: dict, out: str, seed: int = 0) -> dict:
    """`gecgen calibrate` of one manifest row into out/NAME: {name, status "ok", seconds, result (the
    command's JSON)}, or {name, status "failed", seconds, reason (its one line)}. Never raises: a
    robot's failure is its own."""
    from gecgen.cli import main

    argv = ["calibrate", row["robot"], row["train"], "-o", str(Path(out) / row["name"]), "--seed", str(seed), "--json"]
    if row.get("val"):
        argv += ["--val", row["val"]]
    if row.get("holdout"):
        argv += ["--holdout", row["holdout"]]
    if row.get("errors"):
        argv += ["--errors", row["errors"]]
    if row.get("models"):
        argv += ["--models", ",".join(re.split(r"[\s;]+", row["models"].strip()))]
    stdout, stderr = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    try:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            code = main(argv)
        result = json.loads(stdout.getvalue()) if code == 0 else None
    except BaseException as exc:  # noqa: BLE001 - a worker must report, never take the fleet down
        code = 1
        stderr.write(f"gecgen calibrate: {exc.__class__.__name__}: {exc}\n")
    seconds = time.perf_counter() - start
    lines = [ln for ln in stderr.getvalue().splitlines() if ln.strip()]
    if code == 0:
        return {"name": row["name"], "status": "ok", "seconds": seconds, "result": result,
                "warnings": [ln for ln in lines if ": warning: " in ln]}
    reason = next((ln for ln in reversed(lines) if ": warning: " not in ln), "failed without a reason")
    return {"name": row["name"], "status": "failed", "seconds": seconds,
            "reason": reason.removeprefix("gecgen calibrate: ")}


def calibrate_fleet(manifest, out, scheduler: str | None = None, workers: int = 2, seed: int = 0,
                    timeout: float | None = None, progress=None) -> list[dict]:
    """Calibrate every robot of the manifest (`read_manifest`) into out/NAME as tasks on Dask: the
    scheduler at `scheduler`, else a local cluster of `workers` processes (one thread each: a fit
    uses one BLAS thread). Returns `calibrate_one`'s results in manifest order, and writes
    out/fleet.json and out/fleet.csv. progress(done, failed, robots) is called as each robot ends."""
    require(importlib.util.find_spec("distributed") is not None,  # what is missing, said before any work
            "gecgen fleet runs on Dask: pip install 'gecgen[fleet]' (dask[distributed])")
    require(scheduler is None or ADDRESS.match(scheduler), f"--scheduler {excerpt(scheduler)}: give a Dask "
                                                           f"scheduler's address, e.g. tcp://10.0.0.5:8786")
    require(isinstance(workers, int) and not isinstance(workers, bool) and workers >= 1,
            f"workers={workers!r}: give the local cluster's processes as a whole number, 1 or more (the workers "
            f"keyword; --workers on the command line)")
    robots = read_manifest(manifest)
    out = Path(out)
    with output_lock(out, "fleet folder"):
        try:
            results = _run_tasks(robots, out, scheduler, workers, seed, timeout, progress)
            # the mark goes last: a run stopped while writing the summary leaves the folder marked
            write_atomically(out / SUMMARY, json.dumps(results, indent=1))
            write_csv(out / TABLE, ["name", "status", "model", "train_rms_mm", "val_rms_mm", "seconds", "reason"],
                      ([r["name"], r["status"], r.get("result", {}).get("model", ""), _figure(r, "train"),
                        _figure(r, "val"), f"{r['seconds']:.3g}", r.get("reason", "")] for r in results))
        except KeyboardInterrupt as exc:
            state = f"is marked incomplete ({out / MARK})" if (out / MARK).exists() else "is as it was before this run"
            raise type(exc)(f"{out} {state}: run the fleet again") from None
        (out / MARK).unlink()
    return results


def _run_tasks(robots: list[dict], out: Path, scheduler: str | None, workers: int, seed: int,
               timeout: float | None, progress=None) -> list[dict]:
    """`calibrate_one` of every robot as a task on Dask (see `calibrate_fleet`), the results in
    manifest order; progress(done, failed, robots) as each robot ends."""
    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    with contextlib.ExitStack() as stack:
        # Dask's own log lines (a socket closed late, a port in use) are not the user's business:
        # a failure reaches the user as a robot's reason or an exception
        # (nor is what asyncio says of the client's gather when Ctrl-C cut it short)
        stack.enter_context(_quiet("distributed"))
        stack.enter_context(_quiet("asyncio"))
        if scheduler:
            try:
                client = stack.enter_context(Client(scheduler, timeout=timeout) if timeout else Client(scheduler))
            except (OSError, TimeoutError) as exc:
                raise ModelError(f"--scheduler {scheduler}: no Dask scheduler answers there ({exc.__class__.__name__});"
                                 f" start one (dask scheduler) or leave --scheduler out for a local cluster") from None
        else:
            # no dashboard, so no use for the workers' statistical profiler, which samples the task's
            # stack every 10 ms, holding the interpreter the task runs in
            stack.enter_context(dask.config.set({"distributed.worker.profile.enabled": False}))
            # the scheduler's HTTP server (health checks) listens even without a dashboard: on a free
            # port, not on the dashboard's 8787, which another cluster may hold
            cluster = stack.enter_context(LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                scheduler_kwargs={"dashboard_address": ":0"}, silence_logs=logging.CRITICAL,
                preload=[*dask.config.get("distributed.worker.preload"), __name__]))
            client = stack.enter_context(Client(cluster))
        _begin(out)
        # pure=False: two rows with the same files are two robots, each run
        futures = [client.submit(calibrate_one, row, str(out), seed, key=f"calibrate-{row['name']}", pure=False)
                   for row in robots]
        done, failed = 0, 0
        for future in as_completed(futures):
            done, failed = done + 1, failed + (future.result()["status"] != "ok")
            if progress:
                progress(done, failed, len(futures))
        return [f.result() for f in futures]


def _begin(out: Path):
    """Mark the fleet folder as being written, once the cluster is there to write it (a scheduler
    that does not answer leaves the folder as it was): `fleet.incomplete` in, the summary of an
    earlier run, which would not describe the folder, out."""
    out.mkdir(parents=True, exist_ok=True)
    write_atomically(out / MARK, "a gecgen fleet run into this folder has not finished (or was interrupted): its "
                                 "robots' folders may be of different runs; run the fleet again\n")
    for name in (SUMMARY, TABLE):
        (out / name).unlink(missing_ok=True)


def dask_setup(worker):
    """Dask's preload hook (`_run_tasks`), run in each process of the local cluster as it starts:
    Ctrl-C, which a terminal sends to every process of the command, is the fleet's to handle (it
    closes the cluster); a worker told it too would print its own traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def _quiet(name: str):
    """The logger `name` and its children say nothing below CRITICAL while the block runs."""
    logger = logging.getLogger(name)
    before = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(before)


def _figure(result: dict, key: str) -> str:
    value = result.get("result", {}).get(key, {}).get("rms_mm")
    return "" if value is None else f"{value:.4g}"


def run(args) -> dict:
    from gecgen.cli import Incomplete

    start = time.perf_counter()
    with progress_status(not args.json) as status:
        say(status, f"starting the Dask cluster and {args.manifest}'s robots")
        results = calibrate_fleet(args.manifest, args.output, args.scheduler, args.workers, args.seed, args.timeout,
                                  lambda done, failed, n: say(status, f"{done} of {n} robots done ({failed} failed)"))
    failed = [r for r in results if r["status"] != "ok"]
    for r in failed:
        print(f"gecgen fleet: {r['name']}: {r['reason']}", file=sys.stderr)
    result = {"manifest": str(args.manifest), "output": str(args.output), "robots": len(results),
            "ok": len(results) - len(failed), "failed": len(failed), "seconds": time.perf_counter() - start,
            "results": [{k: v for k, v in r.items() if k != "result"} | (
                {"model": r["result"]["model"], "train": r["result"]["train"],
                 **({"val": r["result"]["val"]} if "val" in r["result"] else {})} if "result" in r else {})
                for r in results],
            "files": {"json": str(Path(args.output) / SUMMARY), "csv": str(Path(args.output) / TABLE)}}
    if failed:
        others = "; the others are calibrated" if len(failed) < len(results) else ""
        raise Incomplete(f"{len(failed)} of {len(results)} robots failed: {', '.join(r['name'] for r in failed)}"
                         f"{others}", result)
    return result
