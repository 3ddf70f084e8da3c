"""Batch jobs and their scale-out on Dask (issue 24; docs/scale-out.md).

A job is a list of tasks; a task is a call of a module-level function that writes its output files
(atomically, through paramlod.core.files.write_atomically) and the list of those files. The jobs:
frames of a scene (``paramlod render --frames / --turntable / --camera-path``, ``render_job``),
slices of a volume (``paramlod glyphs --slices``, paramlod/app/glyphs.py), surfel samplings and
mesh-LOD builds of many files (paramlod/app/surfels_cmd.py, ``mesh_build_job``).

Where they run (``run_job``): in this process, one task after the other (the default, and the twin
every other runner is tested against: the same bytes), or on Dask: ``--workers N`` starts a local
cluster of N processes, ``--gpus all`` one process per OpenCL GPU, each pinned to its GPU before
it creates its OpenCL context, ``--scheduler ADDRESS`` an existing cluster (dask-jobqueue on
SLURM). Outputs that exist and are valid are skipped (resume); a worker that dies has its task
run again elsewhere; a bad input stops the job with that input's ParamlodError message; one tqdm
bar covers the job and the report gives every worker's throughput. ``bench_scaling`` measures
frames per second against the worker count (``paramlod bench`` wires it).
"""
from __future__ import annotations

import argparse
import glob
import importlib.util
import json
import logging
import math
import os
import re
import subprocess
import sys
import time
import tomllib
import uuid
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from paramlod.app.args import check_folder, non_negative_int, parse_size, positive_int
from paramlod.app.scenefile import file_object_kind, load_scene
from paramlod.core.camera import Camera
from paramlod.core.files import write_atomically
from paramlod.device import context as device_context
from paramlod.errors import MeshError, ParamlodError, SceneError
from paramlod.function import registry
from paramlod.meshlod.format import SUFFIX as MESHLOD_SUFFIX, load_meshlod, mesh_info, save_meshlod
from paramlod.meshlod.source import load_mesh
from paramlod.pipeline.driver import render
from paramlod.scene.framing import framing_camera, scene_box

DEFAULT_FPS = 24.0
DEFAULT_RETRIES = 2
IMAGE_SUFFIXES = (".png", ".exr")
VIDEO_SUFFIXES = (".gif", ".mp4")
_NO_FFMPEG = "--video {}: MP4 needs imageio-ffmpeg: pip install imageio-ffmpeg (or write a .gif)"
# every task of a job and its output names are made (about 1 KB each) before the first task runs
MAX_JOB_TASKS = 100_000
WORKERS_PER_CORE = 4   # --workers: more local processes than this only add start-up time and memory
# what str.format raises for a bad name pattern ({frmae}, {frame[0]}, {frame.x}, {frame:q})
PATTERN_ERRORS = (KeyError, IndexError, TypeError, AttributeError, ValueError)


# --- the job model ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Task:
    """One unit of a job: ``fn(*args)`` writes ``outputs``; ``check(path)`` says whether an existing
    output is complete (resume); ``name`` is what errors and the report call it."""
    name: str
    fn: Callable
    args: tuple
    outputs: tuple[str, ...]
    check: Callable | None = None


@dataclass(frozen=True)
class WorkerSetup:
    """What a worker process needs before its first task: the OpenCL device selector
    (``--cl-device``) and the plugin folders (``--functions``); applied once per process."""
    cl_device: str | None = None
    functions: tuple[str, ...] = ()

    @classmethod
    def from_args(cls, args) -> "WorkerSetup":
        folders = getattr(args, "functions", None) or ()
        return cls(getattr(args, "cl_device", None), tuple(str(Path(f).expanduser().resolve()) for f in folders))


@dataclass
class Job:
    tasks: list[Task]
    unit: str = "frame"                      # what one task makes, for the bar and the report
    setup: WorkerSetup = field(default_factory=WorkerSetup)
    finish: Callable | None = None           # finish(report), in this process after every task (videos)
    products: list[str] = field(default_factory=list)   # what finish writes


@dataclass
class Outcome:
    """What a task sends back: who ran it, how long it took, and its error when the input was bad."""
    name: str
    worker: str
    seconds: float
    info: dict = field(default_factory=dict)
    error: ParamlodError | None = None


@dataclass
class JobReport:
    done: list[Outcome]
    skipped: list[str]
    seconds: float          # from the first task sent to the last one back
    where: str
    unit: str
    startup_s: float = 0.0  # starting (or reaching) the cluster

    def per_worker(self) -> dict[str, dict]:
        out: dict[str, dict] = {}
        for o in self.done:
            w = out.setdefault(o.worker, {"tasks": 0, "busy_s": 0.0, "device": o.info.get("device")})
            w["tasks"] += 1
            w["busy_s"] += o.seconds
        for w in out.values():
            w["per_s"] = w["tasks"] / w["busy_s"] if w["busy_s"] > 0 else math.inf
        return out

    def summary(self) -> str:
        n = len(self.done)
        rate = f", {n / self.seconds:.2f} {self.unit}s/s" if n and self.seconds > 0 else ""
        skip = f", {len(self.skipped)} already done (skipped)" if self.skipped else ""
        start = f" (+{self.startup_s:.1f} s to start the cluster)" if self.startup_s else ""
        lines = [f"{n} {self.unit}(s) made in {self.seconds:.2f} s{start} on {self.where}{rate}{skip}"]
        for name, w in sorted(self.per_worker().items()):
            dev = f" on {w['device']}" if w["device"] else ""
            lines.append(f"  worker {name}{dev}: {w['tasks']} {self.unit}(s), {w['busy_s']:.2f} s busy, "
                         f"{w['per_s']:.2f} {self.unit}s/s")
        return "\n".join(lines)


# --- per-process state ---------------------------------------------------------------------------
# A Dask worker is a process that runs many tasks, one at a time (threads_per_worker=1). What is
# expensive to make (the loaded scene, and with it its device buffers, plus the OpenCL programs
# in cl_device().cache) is kept here between tasks, so a worker builds its programs once. The key
# holds the scene file's modification time: a scene edited between two jobs on a long-lived
# cluster is loaded again. Few entries: a worker of a cluster that serves many jobs must not
# keep every scene it ever drew.
_STATE: dict = {"setup": None, "scenes": OrderedDict(), "paths": {}, "loads": 0}
_MAX_SCENES = 4


def _apply_setup(setup: WorkerSetup | None):
    if setup is None or _STATE["setup"] == setup:
        return
    if setup.cl_device:
        device_context.set_cl_device(setup.cl_device)
    for folder in setup.functions:
        registry.add_plugin_path(folder)
    _STATE.update(setup=setup, scenes=OrderedDict())


def _worker_name() -> str:
    try:
        from distributed import get_worker

        w = get_worker()
        return f"{w.name} (pid {os.getpid()})"
    except (ImportError, ValueError):
        return f"local (pid {os.getpid()})"


def _execute(setup: WorkerSetup | None, fn: Callable, args: tuple, name: str) -> Outcome:
    """Run one task where it is sent. A ParamlodError (a bad input) comes back as the outcome's
    error, not raised: Dask would retry it (the same input fails the same way) and the client
    would see a remote traceback."""
    t0 = time.perf_counter()
    try:
        _apply_setup(setup)
        info = fn(*args) or {}
    except ParamlodError as exc:
        return Outcome(name, _worker_name(), time.perf_counter() - t0, error=exc)
    return Outcome(name, _worker_name(), time.perf_counter() - t0, info)


def _failed(outcome: Outcome) -> ParamlodError:
    """The task's error, with the task named, as the same ParamlodError class (no traceback)."""
    exc = outcome.error
    try:
        return type(exc)(f"{outcome.name}: {exc}")
    except TypeError:   # a subclass with another constructor
        return ParamlodError(f"{outcome.name}: {exc}")


# --- where a job runs ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Where:
    """Serial (all None), ``workers`` local processes, ``gpus`` ("all" or "0,2": one worker per
    usable OpenCL GPU) or an existing ``scheduler`` address. ``retries``: how often a task is run
    again after its worker died or it raised an unexpected error. ``threads``: PoCL threads per
    local worker (default: the cores shared among the workers)."""
    workers: int | None = None
    gpus: str | None = None
    scheduler: str | None = None
    retries: int = DEFAULT_RETRIES
    threads: int | None = None

    def __post_init__(self):   # the command line's checks, for Where built in Python too
        checks = (("workers", _local_workers), ("gpus", _gpus), ("scheduler", _scheduler),
                  ("retries", non_negative_int), ("threads", positive_int))
        for name, check in checks:
            value = getattr(self, name)
            if value is not None:
                try:
                    check(str(value))
                except argparse.ArgumentTypeError as exc:
                    raise ParamlodError(f"Where {name}: {exc}") from None

    @property
    def serial(self) -> bool:
        return not (self.workers or self.gpus or self.scheduler)

    @classmethod
    def from_args(cls, args) -> "Where":
        return cls(getattr(args, "workers", None), getattr(args, "gpus", None), getattr(args, "scheduler", None),
                   getattr(args, "retries", DEFAULT_RETRIES))


def _gpus(text: str) -> str:
    t = text.strip().lower()
    if t == "all" or (t and all(p.strip().isdigit() for p in t.split(","))):
        return t
    raise argparse.ArgumentTypeError(f"must be 'all' or GPU indices such as 0,1 (see `paramlod info`), got {text!r}")


def _local_workers(text: str) -> int:
    n, most = positive_int(text), WORKERS_PER_CORE * _cores()
    if n > most:   # hundreds of local workers only start slowly (or never) and fill the memory
        raise argparse.ArgumentTypeError(f"at most {most} local workers ({WORKERS_PER_CORE} per CPU core, "
                                         f"{_cores()} here), got {n}: more only add start-up time and memory")
    return n


def _scheduler(text: str) -> str:
    """A scheduler file (.json, as ``dask scheduler --scheduler-file`` writes) whose address is
    readable, or an address with a port: checked here, since Dask fails late and with a bare
    ValueError or AssertionError."""
    address = text
    if text.endswith(".json"):   # _Cluster reads such a name as a scheduler file
        try:
            data = json.loads(Path(text).read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise argparse.ArgumentTypeError(f"scheduler file {text} does not exist") from None
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise argparse.ArgumentTypeError(f"cannot read the scheduler file {text} ({exc})") from None
        address = data.get("address") if isinstance(data, dict) else None
        if not isinstance(address, str):
            raise argparse.ArgumentTypeError(f"{text} is not a Dask scheduler file (no \"address\"; "
                                             "`dask scheduler --scheduler-file FILE` writes one)")
    try:
        from distributed.comm.addressing import get_address_host_port
    except ImportError:
        return text   # run_job says that Dask is needed (need_dask)
    try:
        get_address_host_port(address)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{address!r} is not a Dask scheduler address ({exc}); give "
                                         "tcp://HOST:PORT or a scheduler file (.json)") from None
    return text


def add_job_options(parser):
    """``--workers N | --gpus all | --scheduler ADDRESS``, ``--retries``, ``--overwrite``."""
    g = parser.add_argument_group("where the job runs (default: in this process, one task after the other)")
    m = g.add_mutually_exclusive_group()
    m.add_argument("--workers", type=_local_workers, metavar="N",
                   help=f"a local Dask cluster of N worker processes (one task at a time each; at most "
                        f"{WORKERS_PER_CORE} per CPU core)")
    m.add_argument("--gpus", type=_gpus, metavar="all|I,J",
                   help="a local Dask cluster of one worker per OpenCL GPU, each pinned to its GPU")
    m.add_argument("--scheduler", type=_scheduler, metavar="ADDRESS",
                   help="an existing Dask cluster: its address (tcp://login1:8786) or scheduler file (.json); "
                        "docs/scale-out.md shows SLURM")
    g.add_argument("--retries", type=non_negative_int, default=DEFAULT_RETRIES, metavar="N",
                   help=f"run a task again up to N times after its worker died (default {DEFAULT_RETRIES})")
    g.add_argument("--overwrite", action="store_true",
                   help="make every output again (default: skip outputs that exist and are valid)")
    return g


def job_requested(args) -> bool:
    return bool(getattr(args, "workers", None) or getattr(args, "gpus", None) or getattr(args, "scheduler", None))


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def usable_gpus(selector: str | None = None) -> list[dict]:
    """The OpenCL GPUs the renderers can use (64-bit atomics), optionally those whose name or
    platform contains ``selector``: dicts of platform, name, vendor, ordinal (the device's index
    among its platform's GPUs, ordered by PCI bus where the driver says it) and pci."""
    import pyopencl as cl

    found = []
    devices = device_context.list_devices()
    for d in devices:
        if not d.type & cl.device_type.GPU:
            continue
        try:
            pci = int(d.pci_bus_id_nv)   # NVIDIA's PCI bus: the order CUDA_DEVICE_ORDER=PCI_BUS_ID uses
        except (cl.Error, AttributeError):
            pci = None
        found.append({"platform": d.platform.name.strip(), "name": d.name.strip(), "vendor": d.vendor.strip(),
                      "pci": pci, "usable": device_context.REQUIRED_EXTENSION in d.extensions})
    for plat in {g["platform"] for g in found}:
        mine = [g for g in found if g["platform"] == plat]
        order = sorted(range(len(mine)), key=lambda k: (mine[k]["pci"] is None, mine[k]["pci"] or 0, k))
        for rank, k in enumerate(order):
            mine[k]["ordinal"] = rank
    sel = (selector or "").lower()
    return [g for g in found if g["usable"] and (not sel or sel in g["name"].lower() or sel in g["platform"].lower())]


def gpu_worker_envs(gpus: list[dict], pick: str = "all") -> list[dict]:
    """The environment of one worker per picked GPU, pinning it before its first cl_device():
    PARAMLOD_CL_DEVICE names the GPU; GPUs that share a name are told apart by the driver's
    visibility variable (NVIDIA: CUDA_VISIBLE_DEVICES in PCI order; AMD: GPU_DEVICE_ORDINAL)."""
    if not gpus:
        raise ParamlodError("--gpus: no OpenCL GPU with " + device_context.REQUIRED_EXTENSION + " was found "
                            "(`paramlod info` lists the devices); use --workers N for CPU workers")
    if pick == "all":
        chosen = list(range(len(gpus)))
    else:
        chosen = [int(p) for p in pick.split(",")]
        bad = [k for k in chosen if k >= len(gpus)]
        if bad or len(set(chosen)) != len(chosen):
            raise ParamlodError(f"--gpus {pick}: there are {len(gpus)} usable GPUs (indices 0..{len(gpus) - 1}, "
                                "each at most once; `paramlod info` lists them)")
    envs = []
    for k in chosen:
        g = gpus[k]
        env = {"PARAMLOD_CL_DEVICE": g["name"]}
        twins = [h for h in gpus if h["name"] == g["name"]]
        if len(twins) > 1:
            vendor = (g["vendor"] + " " + g["platform"]).lower()
            if "nvidia" in vendor:
                env.update(CUDA_DEVICE_ORDER="PCI_BUS_ID", CUDA_VISIBLE_DEVICES=str(g["ordinal"]))
            elif "amd" in vendor or "advanced micro" in vendor:
                env["GPU_DEVICE_ORDINAL"] = str(g["ordinal"])
            else:
                raise ParamlodError(f"--gpus: {len(twins)} GPUs are named '{g['name']}' ({g['platform']}) and this "
                                    "driver has no known variable to show a process one of them; start one Dask "
                                    "worker per GPU yourself and pass --scheduler (docs/scale-out.md)")
        envs.append(env)
    return envs


class _Cluster:
    """A Dask client on a local cluster (one worker per environment) or on ``scheduler``."""

    def __init__(self, where: Where, setup: WorkerSetup):
        self.where, self.setup = where, setup
        self.cluster = self.client = None

    def describe(self) -> str:
        w = self.where
        if w.scheduler:
            n = len(self.client.scheduler_info()["workers"])
            return f"the Dask cluster at {w.scheduler} ({n} workers)"
        return f"{len(self.envs)} local {'GPU ' if w.gpus else ''}worker(s)"

    def __enter__(self):
        import dask   # run_job and bench_scaling have checked that it is installed (need_dask)
        from distributed import Client, Nanny, Scheduler, SpecCluster
        w = self.where
        # a worker that died while running a task counts as one failure of that task
        dask.config.set({"distributed.scheduler.allowed-failures": max(0, w.retries)})
        if w.scheduler:
            try:   # an address, or the JSON file `dask scheduler --scheduler-file` writes
                if w.scheduler.endswith(".json") and Path(w.scheduler).is_file():
                    self.client = Client(scheduler_file=w.scheduler, timeout="20s")
                else:
                    self.client = Client(w.scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise ParamlodError(f"--scheduler {w.scheduler}: cannot reach the Dask scheduler ({exc}); start one "
                                    "with `dask scheduler` and workers with `dask worker ADDRESS --nthreads 1`") from None
            return self
        if w.gpus:
            envs = gpu_worker_envs(usable_gpus(self.setup.cl_device), w.gpus)
            self.setup = WorkerSetup(None, self.setup.functions)   # the environment pins each worker's GPU
        else:
            env = {"PARAMLOD_CL_DEVICE": self.setup.cl_device} if self.setup.cl_device else {}
            # CPU workers (PoCL) share the cores instead of each starting a thread per core
            env["POCL_MAX_PTHREAD_COUNT"] = os.environ.get(
                "POCL_MAX_PTHREAD_COUNT", str(w.threads or max(1, _cores() // w.workers)))
            envs = [dict(env) for _ in range(w.workers)]
        self.envs = envs
        kind = "gpu" if w.gpus else "cpu"
        workers = {f"{kind}{k}": {"cls": Nanny, "options": {"nthreads": 1, "env": e, "host": "127.0.0.1",
                                                               "silence_logs": logging.ERROR}}
                   for k, e in enumerate(envs)}
        self.cluster = SpecCluster(workers=workers, silence_logs=logging.ERROR,
                                   scheduler={"cls": Scheduler, "options": {"dashboard": False, "dashboard_address": ":0",
                                                                            "host": "127.0.0.1"}})
        self.client = Client(self.cluster)
        return self

    def __exit__(self, *exc):
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()


# --- running a job ---------------------------------------------------------------------------------
def _is_done(task: Task) -> bool:
    return all(Path(p).is_file() and (task.check is None or task.check(p)) for p in task.outputs)


def _clear_leftovers(task: Task):
    """Temporary files of write_atomically that a killed worker left beside the outputs."""
    for p in task.outputs:
        p = Path(p)
        for tmp in glob.glob(str(p.parent / (glob.escape(f".{p.name}.") + "*" + glob.escape(p.suffix)))):
            try:
                os.unlink(tmp)
            except OSError:
                pass


def _prepare_outputs(todo: list[Task]):
    for t in todo:
        for p in t.outputs:
            Path(p).parent.mkdir(parents=True, exist_ok=True)
        _clear_leftovers(t)


def need_dask(what: str) -> None:
    """A ParamlodError saying that ``what`` needs Dask, when its distributed scheduler is not installed."""
    if importlib.util.find_spec("distributed") is None:
        raise ParamlodError(f"{what} need Dask's distributed scheduler: pip install 'paramlod[dist]'")


def run_job(job: Job, where: Where | None = None, progress: bool = True, overwrite: bool = False) -> JobReport:
    """Run every task of ``job`` whose outputs are not already there and valid; the report of what
    ran where. A task's bad input raises its ParamlodError (naming the task) after the other tasks
    were cancelled; outputs already written stay (a rerun resumes)."""
    from tqdm import tqdm

    where = where or Where()
    done_before = [not overwrite and _is_done(t) for t in job.tasks]
    todo = [t for t, d in zip(job.tasks, done_before) if not d]
    skipped = [t.name for t, d in zip(job.tasks, done_before) if d]
    if todo and not where.serial:
        need_dask("--workers, --gpus and --scheduler")
    _prepare_outputs(todo)
    bar = tqdm(total=len(job.tasks), initial=len(job.tasks) - len(todo), unit=job.unit, disable=not progress,
               file=sys.stderr, dynamic_ncols=True)
    done: list[Outcome] = []
    startup = 0.0
    try:
        if where.serial or not todo:
            label = "this process" if todo else "nothing left to run"
            t0 = time.perf_counter()
            for t in todo:
                o = _execute(None, t.fn, t.args, t.name)
                if o.error is not None:
                    raise _failed(o)
                done.append(o)
                bar.update(1)
        else:
            t_start = time.perf_counter()
            with _Cluster(where, job.setup) as c:
                label = c.describe()
                bar.set_description(label)
                t0 = time.perf_counter()
                startup = t0 - t_start
                _run_on(c.client, c.setup, todo, where.retries, done, bar)
                seconds = time.perf_counter() - t0
    finally:
        bar.close()
    if where.serial or not todo:
        seconds = time.perf_counter() - t0
    report = JobReport(done, skipped, seconds, label, job.unit, startup)
    if job.finish is not None:
        job.finish(report)
    return report


def _run_on(client, setup: WorkerSetup, todo: list[Task], retries: int, done: list, bar):
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    _prepare_outputs(todo)
    tag = uuid.uuid4().hex[:8]   # keys of this run: a rerun on a shared cluster is not served stale results
    futures = {client.submit(_execute, setup, t.fn, t.args, t.name, key=f"paramlod-{tag}-{i}", pure=False,
                             retries=retries): t for i, t in enumerate(todo)}
    try:
        for fut in as_completed(futures):
            task = futures[fut]
            if fut.status == "error":
                exc = fut.exception()
                if isinstance(exc, KilledWorker):
                    raise ParamlodError(f"{task.name}: the workers running it died {retries + 1} time(s) (out of "
                                        "memory, or a crash in the device driver?); --retries N allows more")
                raise exc   # a bug, not an input: its traceback is wanted
            o = fut.result()
            if o.error is not None:
                raise _failed(o)
            done.append(o)
            bar.update(1)
            bar.set_postfix_str(o.worker, refresh=False)
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)


# --- output names and checks -----------------------------------------------------------------------
def parse_range(text: str):
    """``A:B`` (A..B-1), ``A:B:S``, ``K`` (one) or ``all`` -> (a, b, s) or "all" (argparse type)."""
    t = text.strip().lower()
    if t == "all":
        return "all"
    try:
        parts = [int(p) for p in t.split(":")]
        if len(parts) == 1:
            parts = [parts[0], parts[0] + 1]
        if len(parts) == 2:
            parts.append(1)
        a, b, s = parts
        if len(parts) != 3 or a < 0 or b <= a or s < 1:
            raise ValueError
        return a, b, s
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be A:B (A to B-1), A:B:STEP, one number or 'all', with "
                                         f"0 <= A < B, got {text!r}") from None


def expand_range(spec, total: int | None, what: str = "frames") -> list[int]:
    if spec == "all":
        if total is None:
            raise ParamlodError(f"--{what} all: nothing says how many there are; give --{what} A:B")
        indices = range(total)
    else:
        indices = range(*spec)
    if len(indices) > MAX_JOB_TASKS:
        given = spec if spec == "all" else f"{indices.start}:{indices.stop}" + (
            f":{indices.step}" if indices.step > 1 else "")
        raise ParamlodError(f"--{what} {given}: {len(indices)} {what}; one job takes at most {MAX_JOB_TASKS} (every "
                            f"task and output name is made before the first runs): split it into several jobs of "
                            f"--{what} A:B")
    return list(indices)


def format_outputs(patterns, what: str, items: list[dict], suffixes=IMAGE_SUFFIXES,
                   example: str = "out/frame_{frame:04d}") -> list[tuple[str, ...]]:
    """Each item's output paths (absolute), from ``patterns`` with fields such as {frame:04d};
    a pattern that names two items the same, an unknown field or suffix is refused upfront."""
    for p in patterns:
        if Path(p).suffix.lower() not in suffixes:
            raise ParamlodError(f"-o {p}: the output must end with {' or '.join(suffixes)}")
    fields = ", ".join("{" + k + "}" for k in items[0]) if items else ""
    out, seen = [], {}
    for it in items:
        names = []
        for p in patterns:
            try:
                name = str(Path(p.format(**it)).expanduser().resolve())
            except PATTERN_ERRORS as exc:
                raise ParamlodError(f"-o {p}: not a usable name pattern ({type(exc).__name__}: {exc}); the fields "
                                    f"are {fields}, e.g. {example}{suffixes[0]}") from None
            if name in seen:
                raise ParamlodError(f"-o {p}: {len(items)} {what} would share the name {name}; put a field in the "
                                    f"name ({fields}), e.g. {example}{Path(p).suffix}")
            seen[name] = True
            names.append(name)
        out.append(tuple(names))
    # every folder the job writes into is made and probed now, before any task runs
    pattern_of = {str(Path(n).parent): p for names in out for n, p in zip(names, patterns)}
    for folder, p in pattern_of.items():
        check_folder(folder, f"-o {p}", create=True)
    return out


def valid_image(path, size: tuple[int, int]) -> bool:
    """A PNG or EXR file that opens, is not truncated and has ``size`` (w, h)."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".exr":
            import OpenEXR

            with OpenEXR.File(str(path)) as f:
                (x0, y0), (x1, y1) = f.header()["dataWindow"]
                return (int(x1 - x0 + 1), int(y1 - y0 + 1)) == tuple(size)
        from PIL import Image

        with Image.open(path) as img:
            if img.size != tuple(size):
                return False
            img.load()   # decodes every row: a cut file fails here
        return True
    except Exception:   # any reader failure means: not a finished output, make it again
        return False


# --- render jobs: times, turntables, camera paths -------------------------------------------------
@dataclass(frozen=True)
class RenderSpec:
    """What every frame of one scene's render job shares; frame i is at time t0 + i dt."""
    scene: str
    size: tuple | None
    variant: str | None
    aa: str | None
    t0: float
    dt: float
    turntable: int = 0                  # frames per turn; 0: the scene's camera (or the path's)
    camera_path: str | None = None      # a TOML file holding a [camera_path] table


def prepare_scene(path, size=None, variant=None, aa=None, cache: bool = True):
    """(SceneFile, the variant to draw it with): the scene file with ``paramlod render``'s
    --size, --variant and --aa applied; kept per process (see _STATE)."""
    e = _scene_entry(path, size, variant, aa, cache)
    return e["sf"], e["variant"]


def _scene_entry(path, size, variant, aa, cache: bool = True) -> dict:
    """The cached scene file and what is derived from it once (its box, turntable orbits)."""
    path = Path(path)
    try:
        mtime = path.stat().st_mtime_ns
    except OSError:
        mtime = None   # load_scene reports the missing file
    key = (str(path.resolve()), mtime, tuple(size) if size else None, variant, aa)
    scenes = _STATE["scenes"]
    if cache and key in scenes:
        scenes.move_to_end(key)
        return scenes[key]
    sf = load_scene(path, size=size)
    _STATE["loads"] += 1
    if aa:
        v = variant or (None if sf.object_variants else sf.variant)
        sf.settings.apply_aa(aa, points_only=v == "points", variant=v)
    if variant:   # --variant draws every object with it (meshes with the mesh variant that goes with it)
        for obj in [*sf.scene.objects, *sf.scene.meshes]:
            obj.variant = obj.aa = None
        sf.scene.touch()
    entry = {"sf": sf, "variant": variant or sf.variant, "box": None, "orbits": {}}
    if cache:
        scenes[key] = entry
        while len(scenes) > _MAX_SCENES:
            scenes.popitem(last=False)
    return entry


def _raw_tables(path) -> dict:
    """The scene file's TOML (load_scene has validated what it knows of it); {} for a mesh or
    surfel file drawn alone."""
    if file_object_kind(path):
        return {}
    return tomllib.loads(Path(path).read_text(encoding="utf-8"))


def _rotation(axis, degrees: float) -> np.ndarray:
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    th = np.radians(degrees)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * (k @ k)


def _turntable(entry: dict, n: int) -> dict:
    """The orbit of a turntable of ``n`` frames: pivot, axis, start direction and distance.
    The axis is the scene's up; the pivot the camera's target (an eye camera) or the scene's
    box centre (a framing camera, which is framed again for every angle and the farthest distance
    kept, so that the object neither leaves the frame nor breathes)."""
    if n in entry["orbits"]:
        return entry["orbits"][n]
    sf = entry["sf"]
    cam_t = _raw_tables(sf.path).get("camera", {})
    up = np.asarray(cam_t.get("up", [0.0, 1.0, 0.0]), float)
    cam = sf.camera
    if "eye" in cam_t:
        pivot = np.asarray(cam_t.get("target", [0.0, 0.0, 0.0]), float)
        d0 = cam.eye - pivot
        orbit = {"pivot": pivot, "d0": d0 / np.linalg.norm(d0), "dist": float(np.linalg.norm(d0)),
                 "near": cam.near, "far": cam.far}
    else:
        lo, hi = scene_box(sf.scene)
        pivot = (lo + hi) / 2
        d0 = cam.eye - pivot
        d0 /= np.linalg.norm(d0)
        margin = cam_t.get("margin", 1.1)
        dist = max(float(np.linalg.norm(framing_camera(sf.scene, _rotation(up, 360.0 * i / n) @ d0, up, cam.fov_y,
                                                       cam.size, margin).eye - pivot)) for i in range(n))
        radius = float(np.linalg.norm(hi - lo) / 2) or 1.0
        # framing_camera's depth range for a sphere around the box, at the kept distance
        orbit = {"pivot": pivot, "d0": d0, "dist": dist, "near": max(dist - 1.2 * radius, dist * 1e-3),
                 "far": dist + 1.2 * radius}
    orbit["up"] = up
    entry["orbits"][n] = orbit
    return orbit


def turntable_camera(orbit: dict, angle: float, fov_y: float, size) -> Camera:
    d = _rotation(orbit["up"], angle) @ orbit["d0"]
    return Camera.look_at(orbit["pivot"] + d * orbit["dist"], orbit["pivot"], orbit["up"], fov_y, size,
                          near=orbit["near"], far=orbit["far"])


@dataclass
class CameraPath:
    """Camera keyframes: eye, target, up and fov_y at scene times; between keys linear or smooth
    (Catmull-Rom tangents, C1), before the first and after the last key the end key."""
    times: np.ndarray
    eyes: np.ndarray
    targets: np.ndarray
    ups: np.ndarray
    fovs: np.ndarray
    smooth: bool
    near: float | None
    far: float | None
    source: str

    def _interp(self, values: np.ndarray, t: float) -> np.ndarray:
        ts = self.times
        if len(ts) == 1 or t <= ts[0]:
            return values[0]
        if t >= ts[-1]:
            return values[-1]
        k = int(np.searchsorted(ts, t, side="right")) - 1
        h = ts[k + 1] - ts[k]
        s = (t - ts[k]) / h
        if not self.smooth:
            return values[k] + s * (values[k + 1] - values[k])

        def tangent(j):   # central difference in time; one-sided at the ends
            a, b = max(j - 1, 0), min(j + 1, len(ts) - 1)
            return (values[b] - values[a]) / (ts[b] - ts[a])
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        return h00 * values[k] + h10 * h * tangent(k) + h01 * values[k + 1] + h11 * h * tangent(k + 1)

    def camera(self, t: float, size, box) -> Camera:
        eye, target = self._interp(self.eyes, t), self._interp(self.targets, t)
        up, fov = self._interp(self.ups, t), float(self._interp(self.fovs[:, None], t)[0])
        near, far = self.near, self.far
        if near is None or far is None:   # a depth range around the scene's bounding sphere
            lo, hi = box
            radius = float(np.linalg.norm(hi - lo) / 2) or 1.0
            dist = float(np.linalg.norm(eye - (lo + hi) / 2))
            near = near if near is not None else max(dist - 1.2 * radius, dist * 1e-3, radius * 1e-4)
            far = far if far is not None else dist + 1.2 * radius
        try:
            return Camera.look_at(eye, target, up, fov, size, near=near, far=far)
        except SceneError as exc:
            raise SceneError(f"{self.source}: [camera_path] at t = {t:g}: {exc}") from None

    @property
    def end(self) -> float:
        return float(self.times[-1])


PATH_KEYS = {"keys", "interpolation", "near", "far", "up", "fov_y"}
KEY_KEYS = {"t", "eye", "target", "up", "fov_y"}


def load_camera_path(path, default_up=(0.0, 1.0, 0.0), default_fov: float = 45.0) -> CameraPath:
    """The ``[camera_path]`` table of a TOML file (a scene file or a file of its own), validated::

        [camera_path]
        interpolation = "smooth"      # or "linear" (default)
        [[camera_path.keys]]
        t = 0.0                       # scene time of the key, increasing
        eye = [0, 1, 4]
        target = [0, 0, 0]            # optional: default [0, 0, 0]; up, fov_y optional too
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SceneError(f"camera path file {path} does not exist") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"cannot read the camera path in {path}: {exc}") from None
    table = data.get("camera_path")
    where = f"{path}: camera_path"
    if not isinstance(table, dict):
        raise SceneError(f"{path}: has no [camera_path] table (keys: [[camera_path.keys]] t, eye, target)")
    extra = sorted(set(table) - PATH_KEYS)
    if extra:
        raise SceneError(f"{where}.{extra[0]}: unknown field (allowed: {', '.join(sorted(PATH_KEYS))})")
    interp = table.get("interpolation", "linear")
    if interp not in ("linear", "smooth"):
        raise SceneError(f"{where}.interpolation: must be \"linear\" or \"smooth\", got {interp!r}")
    keys = table.get("keys")
    if not isinstance(keys, list) or not keys:
        raise SceneError(f"{where}.keys: needs at least one [[camera_path.keys]] table with t, eye and target")

    def num(d, k, w, default=None, lo=None, hi=None):
        v = d.get(k, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                or (lo is not None and v <= lo) or (hi is not None and v >= hi):
            rng = f" in ({lo}, {hi})" if lo is not None and hi is not None else (f" > {lo}" if lo is not None else "")
            raise SceneError(f"{w}.{k}: must be a number{rng}, got {v!r}")
        return float(v)

    def vec(d, k, w, default=None):
        v = d.get(k, default)
        if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                            and math.isfinite(x) for x in v)):
            raise SceneError(f"{w}.{k}: must be a list of 3 numbers, got {v!r}")
        return [float(x) for x in v]

    up0 = vec(table, "up", where, list(default_up))
    fov0 = num(table, "fov_y", where, default_fov, 0, 180)
    rows = []
    for i, k in enumerate(keys):
        w = f"{where}.keys[{i}]"
        if not isinstance(k, dict):
            raise SceneError(f"{w}: must be a table with t, eye and target")
        extra = sorted(set(k) - KEY_KEYS)
        if extra:
            raise SceneError(f"{w}.{extra[0]}: unknown field (allowed: {', '.join(sorted(KEY_KEYS))})")
        if "t" not in k or "eye" not in k:
            raise SceneError(f"{w}: needs t (the scene time of the key) and eye")
        rows.append((num(k, "t", w), vec(k, "eye", w), vec(k, "target", w, [0.0, 0.0, 0.0]), vec(k, "up", w, up0),
                     num(k, "fov_y", w, fov0, 0, 180)))
    times = np.array([r[0] for r in rows])
    if np.any(np.diff(times) <= 0):
        raise SceneError(f"{where}.keys: the times t must increase from key to key, got {times.tolist()}")
    near = num(table, "near", where, lo=0) if "near" in table else None
    far = num(table, "far", where, lo=0) if "far" in table else None
    if near is not None and far is not None and not near < far:
        raise SceneError(f"{where}: needs near < far, got near={near}, far={far}")
    return CameraPath(times, *(np.array([r[j] for r in rows], float) for j in (1, 2, 3)),
                      np.array([r[4] for r in rows]), interp == "smooth", near, far, str(path))


def _camera_path(file, fov_y: float) -> CameraPath:
    path = Path(file)
    try:
        mtime = path.stat().st_mtime_ns
    except OSError:
        mtime = None   # load_camera_path reports the missing file
    key = (str(path), mtime, fov_y)
    cp = _STATE["paths"].get(key)
    if cp is None:   # keys without fov_y take the scene camera's
        cp = _STATE["paths"][key] = load_camera_path(path, default_fov=fov_y)
    return cp


def frame_camera(entry: dict, spec: RenderSpec, index: int, t: float) -> tuple[Camera, float]:
    """Frame ``index``'s camera and, for turntables, its angle in degrees."""
    sf = entry["sf"]
    if spec.turntable:
        angle = 360.0 * index / spec.turntable
        return turntable_camera(_turntable(entry, spec.turntable), angle, sf.camera.fov_y, sf.camera.size), angle
    if spec.camera_path:
        if entry["box"] is None:
            entry["box"] = scene_box(sf.scene)
        return _camera_path(spec.camera_path, sf.camera.fov_y).camera(t, sf.camera.size, entry["box"]), 0.0
    return sf.camera, 0.0


def render_frame(spec: RenderSpec, index: int, outputs: tuple[str, ...]) -> dict:
    """The task of a render job: frame ``index`` of ``spec`` drawn and saved to ``outputs``."""
    entry = _scene_entry(spec.scene, spec.size, spec.variant, spec.aa)
    sf = entry["sf"]
    t = spec.t0 + index * spec.dt
    camera, _ = frame_camera(entry, spec, index, t)
    frame = render(sf.scene, camera, variant=entry["variant"], settings=sf.settings, time=t)
    for out in outputs:
        frame.save(out)
    return {"device": frame.stats.get("device") or device_context.cl_device().name,
            "pixels": int(frame.stats["pixels_written"]), "ms": float(frame.stats["ms"]["total"]),
            "scene_loads": _STATE["loads"]}   # scene files this process loaded so far


def image_check(size):
    """check(path) for resume: a PNG or EXR of ``size`` that reads to its end."""
    return _ImageCheck(tuple(size))


@dataclass(frozen=True)
class _ImageCheck:   # a picklable check(path) with the expected size
    size: tuple

    def __call__(self, path) -> bool:
        return valid_image(path, self.size)


def render_job(scenes, outputs=None, frames=None, fps: float | None = None, turntable: int | None = None,
               camera_path=None, size=None, variant: str | None = None, aa: str | None = None,
               video: str | None = None, setup: WorkerSetup | None = None) -> Job:
    """The frames of one or more scene files as a job.

    ``frames``: parse_range's value (default: all frames of a turntable or a camera path, else
    frame 0); frame i is at scene time t0 + i dt, with dt = 1/fps when ``fps`` is given, else the
    [animation] table's (t1 - t0) / frames, else 1/24. ``turntable``: N frames around the scene's
    up axis at fixed time. ``camera_path``: a TOML file with a [camera_path] table (True: the scene
    file's own). ``outputs``: name patterns with {frame}, {time}, {angle}, {scene}. ``video``: a
    .gif or .mp4 (pattern with {scene} for several scenes) made from the PNG frames at the end."""
    scenes = [Path(s) for s in scenes]
    if turntable is not None and camera_path:
        raise ParamlodError("--turntable and --camera-path both set the camera; give one of them")
    if turntable is not None and not 1 <= turntable <= MAX_JOB_TASKS:   # the orbit is framed at every angle
        raise ParamlodError(f"--turntable N needs 1 <= N <= {MAX_JOB_TASKS} frames, got {turntable}")
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise ParamlodError(f"--fps must be a number > 0, got {fps}")
    if video is not None:
        if Path(video).suffix.lower() not in VIDEO_SUFFIXES:
            raise ParamlodError(f"--video {video}: must end with .gif or .mp4")
        if Path(video).suffix.lower() == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is None:
            raise ParamlodError(_NO_FFMPEG.format(video))   # before the frames, not after them
        if len(scenes) > 1 and "{scene" not in video:
            raise ParamlodError(f"--video {video}: {len(scenes)} scenes need one video each: put {{scene}} in "
                                "the name, e.g. out/{scene}.gif")
        for scene in scenes:
            try:
                video.format(scene=scene.stem)
            except PATTERN_ERRORS as exc:
                raise ParamlodError(f"--video {video}: not a usable name pattern ({type(exc).__name__}: {exc}); "
                                    "the field is {scene}, e.g. out/{scene}.gif") from None
    if outputs is None:
        many = (frames is not None) or turntable or camera_path
        stem = "{scene}_{frame:04d}.png" if many else "{scene}.png"
        outputs = [str(Path("out") / stem)]
    tasks, videos = [], []
    for scene in scenes:
        sf, _ = prepare_scene(scene, size, variant, aa)   # a bad scene file fails here, before any worker starts
        anim = sf.animation
        t0 = float(anim["t0"]) if anim else float(sf.scene.time)
        dt = 1.0 / fps if fps else ((anim["t1"] - anim["t0"]) / anim["frames"] if anim else 1.0 / DEFAULT_FPS)
        rate = fps or (float(anim["fps"]) if anim else DEFAULT_FPS)
        path_file = None
        total = anim["frames"] if anim else None
        if camera_path:
            path_file = str((sf.path if camera_path is True else Path(camera_path)).resolve())
            cp = _camera_path(path_file, sf.camera.fov_y)   # a bad table fails here, before any worker
            if total is None:
                total = int(math.floor((cp.end - t0) / dt + 1e-9)) + 1 if dt > 0 else 1
        if turntable:
            t0, dt, total = t0, 0.0, turntable
        spec = RenderSpec(str(sf.path.resolve()), tuple(size) if size else None, variant, aa, t0, dt,
                          turntable or 0, path_file)
        default = "all" if (turntable or camera_path) else (0, 1, 1)
        indices = expand_range(frames if frames is not None else default, total)
        items = [{"frame": i, "time": t0 + i * dt, "angle": 360.0 * i / turntable if turntable else 0.0,
                  "scene": sf.path.stem} for i in indices]
        names = format_outputs(outputs, "frames" if len(scenes) == 1 else "frames of the scenes", items)
        check = image_check(sf.camera.size)
        for it, outs in zip(items, names):
            label = f"{sf.path.name} frame {it['frame']}" + (f" (t = {it['time']:g})" if dt else "")
            tasks.append(Task(label, render_frame, (spec, it["frame"], outs), outs, check))
        if video is not None:
            pngs = [outs[[Path(o).suffix.lower() for o in outs].index(".png")] for outs in names
                    if ".png" in [Path(o).suffix.lower() for o in outs]]
            if not pngs:
                raise ParamlodError(f"--video {video}: the video is made from the PNG frames; add -o with a .png pattern")
            videos.append((str(Path(video.format(scene=sf.path.stem)).expanduser().resolve()), pngs, rate))
    dup = [t.outputs for t in tasks]
    flat = [o for outs in dup for o in outs]
    if len(set(flat)) != len(flat):
        raise ParamlodError(f"-o {' '.join(outputs)}: several scenes would write the same files; put {{scene}} in "
                            "the name, e.g. out/{scene}_{frame:04d}.png")

    def finish(report):
        for path, pngs, rate in videos:
            write_video(path, pngs, rate)
    return Job(tasks, "frame", setup or WorkerSetup(), finish if videos else None, [v[0] for v in videos])


def write_video(path, frames, fps: float) -> Path:
    """An animated GIF (looping, Pillow) or an MP4 (H.264, imageio-ffmpeg's ffmpeg) of PNG files, atomically."""
    from PIL import Image

    imgs = []
    for f in frames:
        with Image.open(f) as im:
            imgs.append(np.asarray(im.convert("RGB")))
    if len({a.shape for a in imgs}) > 1:
        raise ParamlodError(f"--video {path}: the frames differ in size ({sorted({a.shape[:2] for a in imgs})})")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        ms = max(20, int(round(1000.0 / fps / 10)) * 10)   # GIF delays are hundredths of a second
        pictures = [Image.fromarray(a) for a in imgs]
        return write_atomically(path, lambda tmp: pictures[0].save(tmp, format="GIF", save_all=True,
                                                                   append_images=pictures[1:], duration=ms, loop=0))
    try:
        import imageio_ffmpeg
    except ImportError:
        raise ParamlodError(_NO_FFMPEG.format(path)) from None
    h, w = imgs[0].shape[:2]
    # H.264 in yuv420p needs even sides: pad by repeating the last row/column
    padded = np.stack([np.pad(a, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge") for a in imgs])

    def encode(tmp):   # ffmpeg run here, its messages kept: through imageio they flooded the terminal
        done = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-v", "error", "-f", "rawvideo",
                               "-pix_fmt", "rgb24", "-s", f"{padded.shape[2]}x{padded.shape[1]}", "-r", f"{fps:g}",
                               "-i", "-", "-an", "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-f", "mp4", str(tmp)],
                              input=padded.tobytes(), capture_output=True)
        if done.returncode:   # its first message is the cause, without ffmpeg's "[out#0/mp4 @ 0x...]" tag
            lines = done.stderr.decode(errors="replace").strip().splitlines() or [f"exit status {done.returncode}"]
            raise OSError("ffmpeg failed: " + re.sub(r"^\[[^]]*\] *", "", lines[0]))
    return write_atomically(path, encode)


# --- mesh builds of many files ---------------------------------------------------------------------
def build_mesh_file(source: str, out: str, lod: str, cache: bool) -> dict:
    """The task of ``mesh_build_job``: ``source``'s cluster DAG saved to ``out``."""
    built = load_mesh(source, lod=lod, cache=cache, progress=False)
    save_meshlod(built, out)
    return {"triangles": int(mesh_info(built)["triangles"])}


def valid_meshlod(path) -> bool:
    try:
        load_meshlod(path)
        return True
    except MeshError:
        return False


def mesh_build_job(paths, out: str = "{stem}" + MESHLOD_SUFFIX, lod: str = "dag", cache: bool = True,
                   setup: WorkerSetup | None = None) -> Job:
    """``paramlod mesh build DIR/*``: one task per mesh file, each writing ``out`` (a pattern with
    {stem} and {name}; relative to the mesh's folder unless absolute)."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise MeshError("mesh build: no mesh files given")
    tasks, seen = [], {}
    for p in paths:
        if p.name.lower().endswith(MESHLOD_SUFFIX):
            raise MeshError(f"{p} is already a {MESHLOD_SUFFIX} file; give the mesh file it was built from")
        try:
            name = out.format(stem=p.name.split(".")[0], name=p.name)
        except PATTERN_ERRORS as exc:
            raise MeshError(f"-o {out}: not a usable name pattern ({exc}); the fields are {{stem}} and {{name}}") from None
        target = Path(name) if Path(name).is_absolute() else p.parent / name
        if not target.name.lower().endswith(MESHLOD_SUFFIX):
            raise MeshError(f"-o {out}: the output must be a {MESHLOD_SUFFIX} file")
        target = str(target.resolve())
        if target in seen:
            raise MeshError(f"-o {out}: {seen[target]} and {p} would both be written to {target}; use {{name}}")
        seen[target] = p
        tasks.append(Task(str(p), build_mesh_file, (str(p.resolve()), target, lod, cache), (target,), valid_meshlod))
    return Job(tasks, "mesh", setup or WorkerSetup())


# --- the bench: frames per second against the worker count -----------------------------------------
def _warm(spec: RenderSpec, outputs) -> dict:
    return render_frame(spec, 0, outputs)


def bench_scaling(scene="gallery/giant_worm.toml", frames: int = 24, size=(320, 240), workers=(1, 2),
                  threads: int | None = None, gpus: str | None = None, out_dir=None, progress: bool = False) -> dict:
    """Frames per second of one scene's animation: serial in this process, then on local clusters
    of each worker count (``threads`` PoCL threads per worker, default the cores over the largest
    count, so that every count has the same threads per worker) and, with ``gpus``, on one
    worker per GPU. Each run writes its PNGs to a fresh folder; cluster start-up and each worker's
    first frame (program builds) are not timed."""
    import tempfile

    need_dask("bench-scale's clusters")
    from distributed import wait

    scene = str(Path(scene).resolve())
    threads = threads or max(1, _cores() // max(workers or (1,)))
    result = {"scene": Path(scene).name, "frames": frames, "size": list(size), "cores": _cores(),
              "threads_per_worker": threads, "device": device_context.cl_device().name, "runs": []}
    with tempfile.TemporaryDirectory(dir=out_dir) as tmp:
        def job(tag):
            return render_job([scene], [str(Path(tmp) / tag / "f_{frame:04d}.png")], frames=(0, frames, 1),
                              size=size)

        warm = job("warm-serial")
        run_job(Job(warm.tasks[:1], "frame"), progress=False)   # builds the programs of this process
        r = run_job(job("serial"), progress=progress)
        serial_fps = frames / r.seconds
        result["runs"].append({"where": "serial", "workers": 0, "fps": serial_fps})
        configs = [(n, Where(workers=n, threads=threads)) for n in workers]
        if gpus:
            configs.append((None, Where(gpus=gpus)))
        for n, where in configs:
            j = job(f"w{n}" if n else "gpu")
            with _Cluster(where, j.setup) as c:
                names = list(c.client.scheduler_info()["workers"])
                spec = j.tasks[0].args[0]
                wait([c.client.submit(_execute, c.setup, _warm, (spec, (str(Path(tmp) / f"warm-{k}.png"),)), "warm",
                                      workers=[a], allow_other_workers=False, pure=False)
                      for k, a in enumerate(names)])
                done: list[Outcome] = []
                from tqdm import tqdm

                with tqdm(total=frames, disable=not progress, file=sys.stderr) as bar:
                    t0 = time.perf_counter()
                    _run_on(c.client, c.setup, j.tasks, DEFAULT_RETRIES, done, bar)
                    seconds = time.perf_counter() - t0
            rep = JobReport(done, [], seconds, where.gpus and "gpus" or f"{n} workers", "frame")
            fps = frames / seconds
            row = {"where": "gpus " + where.gpus if where.gpus else f"{n} workers", "workers": len(names),
                   "fps": fps, "vs_serial": fps / serial_fps,
                   "per_worker": {k: v["tasks"] for k, v in rep.per_worker().items()}}
            result["runs"].append(row)
    one = next((r for r in result["runs"] if r["workers"] == 1 and r["where"].endswith("workers")), None)
    for r in result["runs"]:
        if one is not None and r["where"].endswith("workers"):
            r["efficiency"] = r["fps"] / (r["workers"] * one["fps"])   # 1.0: linear in workers
    return result


def format_bench(res: dict) -> str:
    lines = [f"{res['scene']}: {res['frames']} frames at {res['size'][0]}x{res['size'][1]} on {res['device']}, "
             f"{res['cores']} cores, {res['threads_per_worker']} PoCL thread(s) per worker",
             "  where          fps    vs serial  efficiency (1.0 = linear in workers)"]
    for r in res["runs"]:
        eff = f"{r['efficiency']:.2f}" if "efficiency" in r else "-"
        vs = f"{r['vs_serial']:.2f}x" if "vs_serial" in r else "1.00x"
        lines.append(f"  {r['where']:<12} {r['fps']:7.2f}  {vs:>9}  {eff}")
    return "\n".join(lines)


def add_bench_arguments(p):
    """``paramlod bench-scale``."""
    p.add_argument("--scene", default="gallery/giant_worm.toml", help="an animated scene file")
    p.add_argument("--frames", type=positive_int, default=24, help="frames per run (default 24)")
    p.add_argument("--size", default="320x240", help="frame size WxH (default 320x240)")
    p.add_argument("--workers", default="1,2", help="worker counts, comma separated (default 1,2)")
    p.add_argument("--threads", type=positive_int, help="PoCL threads per CPU worker (default: cores / largest count)")
    p.add_argument("--gpus", type=_gpus, help="also one worker per GPU ('all' or indices)")
    p.add_argument("--json", metavar="FILE", help="write the numbers as JSON")


def run_bench_scaling(args) -> int:
    try:
        size = parse_size(args.size) if isinstance(args.size, str) else args.size
        counts = tuple(_local_workers(x) for x in str(args.workers).split(","))
    except argparse.ArgumentTypeError as exc:
        raise ParamlodError(f"bench-scale: {exc}") from None
    if args.json:   # checked before the runs, which take minutes
        check_folder(Path(args.json).parent, "--json")
    res = bench_scaling(args.scene, args.frames, size, counts, args.threads, args.gpus, progress=True)
    print(format_bench(res))
    if args.json:
        write_atomically(args.json, lambda tmp: Path(tmp).write_text(json.dumps(res, indent=2)))
    return 0
