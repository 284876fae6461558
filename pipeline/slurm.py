"""A SLURM profile against the cluster it submits to: checked before anything is submitted, watched
while the workflow runs.

Snakemake's SLURM executor plugin submits each job with sbatch and polls its state with sacct. Three
cluster conditions would make a sweep wait forever without a word, so they are caught here:

- a job that asks more CPUs or memory than any node has pends forever (reason PartitionConfig):
  `check_profile` refuses it before submitting, naming the profile key to lower;
- without accounting (slurmdbd) sacct fails and the plugin keeps polling: `check_profile` refuses,
  naming the plugin's setting that works without it (``slurm-status-command: squeue``, which the
  project's profile sets: plugin 2.8.0 reads sacct's ``CANCELLED by <uid>`` as still running, so a
  cancelled job would hang the workflow; squeue says ``CANCELLED`` and the retry runs);
- with every node of its partition down or drained, a pending job never starts: `Watch` cancels the
  workflow's pending jobs once no node has taken jobs for ``PIPELINE_SLURM_NODES_GRACE_S`` seconds
  (default 120); Snakemake then fails those jobs and the caller names what did not run.

Only the slurm executor is checked; a dry run needs no cluster and is not checked.
"""

from __future__ import annotations

import logging
import os
import re
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

log = logging.getLogger(__name__)

GRACE_ENV = "PIPELINE_SLURM_NODES_GRACE_S"
DEFAULT_GRACE_S = 120.0
POLL_S = 5.0
COMMAND_TIMEOUT_S = 20
# The plugin waits this long before its first status check (its default of init-seconds-before-status-checks).
PLUGIN_INIT_S = 40
# sinfo's short node states (%t) in which a node takes jobs; a trailing '*' (not responding) rules it out.
TAKING_JOBS = {"idle", "mix", "alloc", "comp", "resv", "plnd", "npc"}
# Reasons for which a pending job never starts without a change to the job or the cluster.
NEVER_STARTS = {"PartitionConfig", "PartitionNodeLimit", "PartitionTimeLimit", "BadConstraints", "InvalidQOS"}


class ClusterError(Exception):
    """The profile cannot run on this cluster; one line that names the key or the setting to change."""


@dataclass(frozen=True)
class Node:
    name: str
    cpus: int
    memory_mb: int
    state: str  # sinfo's short state (%t), e.g. idle, mix, drain, down*


@dataclass(frozen=True)
class Request:
    """What one rule's jobs ask of a node, and the profile key each figure comes from."""

    rule: str
    cpus: int
    memory_mb: int | None
    partition: str | None
    cpus_key: str
    memory_key: str


def profile_settings(profile_dir: Path) -> dict[str, Any]:
    settings = yaml.safe_load((profile_dir / "config.yaml").read_text(encoding="utf-8")) or {}
    return settings if isinstance(settings, dict) else {}


def uses_slurm(settings: dict[str, Any]) -> bool:
    return settings.get("executor") == "slurm"


def _per_rule(value: Any) -> dict[str, Any]:
    """A profile's set-threads or set-resources as a mapping, given as a mapping or 'rule=value' strings."""
    if isinstance(value, dict):
        return value
    if isinstance(value, list):
        return dict(str(item).split("=", 1) for item in value if "=" in str(item))
    return {}


def _as_int(value: Any) -> int | None:
    try:
        return int(value)
    except (TypeError, ValueError):
        return None  # an expression Snakemake evaluates per job; left to the scheduler


def requests(settings: dict[str, Any], rules: dict[str, dict[str, int]]) -> list[Request]:
    """Each submitted rule's CPUs and memory as Snakemake resolves them: the profile's set-threads and
    set-resources, then the rule's own (``rules``: rule -> {threads, mem_mb}), then default-resources."""
    threads = _per_rule(settings.get("set-threads"))
    resources = {rule: value or {} for rule, value in _per_rule(settings.get("set-resources")).items()}
    defaults = settings.get("default-resources") or {}
    if isinstance(defaults, list):
        defaults = dict(str(item).split("=", 1) for item in defaults if "=" in str(item))
    found = []
    for rule, own in rules.items():
        rule_resources = resources.get(rule, {}) if isinstance(resources.get(rule), dict) else {}
        cpus = _as_int(threads.get(rule, own.get("threads", 1))) or 1
        if "mem_mb" in rule_resources:
            memory, memory_key = _as_int(rule_resources["mem_mb"]), f"set-resources.{rule}.mem_mb"
        elif "mem_mb" in own:
            memory, memory_key = own["mem_mb"], f"set-resources.{rule}.mem_mb"
        else:
            memory, memory_key = _as_int(defaults.get("mem_mb")), "default-resources.mem_mb"
        partition = rule_resources.get("slurm_partition", defaults.get("slurm_partition"))
        found.append(Request(rule, cpus, memory, partition, f"set-threads.{rule}", memory_key))
    return found


def _run(command: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command, capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S, check=False)


def _first_error(result: subprocess.CompletedProcess[str]) -> str:
    lines = [line.strip() for line in (result.stderr or result.stdout).splitlines() if line.strip()]
    text = lines[-1] if lines else f"exit {result.returncode}"
    return re.sub(r"^\w+: error: ", "", text)


def cluster_nodes(partition: str | None = None) -> list[Node]:
    """The nodes of ``partition`` (default: the default partition) from sinfo."""
    result = _run(["sinfo", "--noheader", "--Node", "--format=%N|%c|%m|%P|%t"])
    if result.returncode != 0:
        raise ClusterError(f"sinfo failed ({_first_error(result)}): is this a SLURM login node?")
    nodes: dict[str, Node] = {}
    for line in result.stdout.splitlines():
        name, cpus, memory, node_partition, state = line.strip().split("|")
        is_default = node_partition.endswith("*")
        if partition is None and not is_default or partition is not None and node_partition.rstrip("*") != partition:
            continue
        nodes[name] = Node(name, int(cpus), int(re.sub(r"\D", "", memory) or 0), state)
    return list(nodes.values())


def _oversized(request: Request, nodes: list[Node], where: str) -> str | None:
    if not nodes:
        partition = f"partition '{request.partition}'" if request.partition else "the default partition"
        return f"{where}: {request.rule} jobs go to {partition}, which has no nodes: set slurm_partition"
    biggest = max(nodes, key=lambda node: node.cpus)
    if request.cpus > biggest.cpus:
        return (
            f"{where}: {request.cpus_key} = {request.cpus} asks {request.cpus} CPUs but the largest node "
            f"({biggest.name}) has {biggest.cpus}: lower {request.cpus_key} to {biggest.cpus} or less, "
            "or submit to a partition with bigger nodes (slurm_partition)"
        )
    roomiest = max(nodes, key=lambda node: node.memory_mb)
    if request.memory_mb is not None and request.memory_mb > roomiest.memory_mb:
        return (
            f"{where}: {request.memory_key} = {request.memory_mb} asks {request.memory_mb} MB but the largest "
            f"node ({roomiest.name}) has {roomiest.memory_mb} MB: lower {request.memory_key} to "
            f"{roomiest.memory_mb} or less, or submit to a partition with bigger nodes (slurm_partition)"
        )
    return None


def _min_job_age_s() -> int | None:
    result = _run(["scontrol", "show", "config"])
    match = re.search(r"^MinJobAge\s*=\s*(\d+)", result.stdout, re.MULTILINE)
    return int(match.group(1)) if match else None


def _status_problem(settings: dict[str, Any], where: str) -> str | None:
    """Why the plugin could not follow its jobs here, or None.

    With ``slurm-status-command: squeue`` it reads squeue, which keeps a finished job for MinJobAge
    seconds; below 3 x its first wait it polls sacct instead, which needs accounting (slurmdbd)."""
    result = _run(["sacct", "--allocations", "--noheader", "--format=JobID", "--starttime=now"])
    accounting = result.returncode == 0
    init_s = _as_int(settings.get("slurm-init-seconds-before-status-checks")) or PLUGIN_INIT_S
    min_job_age = _min_job_age_s()
    if settings.get("slurm-status-command") == "squeue":
        if min_job_age is not None and min_job_age >= 3 * init_s:
            if not accounting:
                log.warning(
                    "slurm: SLURM accounting is unavailable (sacct: %s); jobs are followed with squeue "
                    "(slurm-status-command: squeue), which needs none",
                    _first_error(result),
                )
            return None
        return (
            f"{where}: slurm-status-command: squeue needs MinJobAge >= 3 x slurm-init-seconds-before-status-checks"
            f" = {3 * init_s} s, and this cluster's MinJobAge is {min_job_age} s (below it the plugin polls sacct"
            f" instead): lower slurm-init-seconds-before-status-checks to {(min_job_age or 0) // 3} or less"
        )
    if accounting:
        return None
    return (
        f"{where}: SLURM accounting is unavailable (sacct: {_first_error(result)}), and the SLURM executor polls "
        "job states with sacct, so it would wait forever: start slurmdbd, or set slurm-status-command: squeue in the "
        f"profile (it needs MinJobAge >= 3 x slurm-init-seconds-before-status-checks = {3 * init_s} s; this "
        f"cluster's MinJobAge is {min_job_age} s)"
    )


def check_profile(profile_dir: Path, rules: dict[str, dict[str, int]]) -> None:
    """Refuse, before submitting, a profile whose jobs this cluster can never run or never follow.

    ``rules``: each rule that goes to the cluster -> its own {threads, mem_mb}."""
    settings = profile_settings(profile_dir)
    if not uses_slurm(settings):
        return
    where = str(profile_dir / "config.yaml")
    for tool in ("sbatch", "sinfo", "squeue"):
        if shutil.which(tool) is None:
            raise ClusterError(
                f"{where}: executor: slurm submits with sbatch, and {tool} is not on PATH: run on a SLURM login node, "
                "or use --profile default"
            )
    try:
        for request in requests(settings, rules):
            problem = _oversized(request, cluster_nodes(request.partition), where)
            if problem:
                raise ClusterError(problem)
        problem = _status_problem(settings, where)
    except subprocess.TimeoutExpired as exc:
        raise ClusterError(f"{where}: {exc.cmd[0]} did not answer in {COMMAND_TIMEOUT_S} s: is slurmctld up?") from None
    if problem:
        raise ClusterError(problem)


# ---------------------------------------------------------------- while the workflow runs


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt  # so that Watch.run stops Snakemake, which cancels its jobs


@dataclass
class Watch:
    """Cancels the workflow's pending jobs that can never start; keeps a line per cancelled job.

    The workflow's jobs are those whose working directory is ``folder`` (Snakemake's --directory)."""

    folder: Path
    grace_s: float = field(default_factory=lambda: float(os.environ.get(GRACE_ENV, DEFAULT_GRACE_S)))
    cancelled: dict[str, str] = field(default_factory=dict)  # job id -> its rule and wildcards, and why
    _unusable_since: dict[str, float] = field(default_factory=dict)

    def run(self, command: list[str]) -> int:
        """Run ``command`` (Snakemake) to its end, looking at the queue every few seconds; its exit code."""
        process = subprocess.Popen(command)
        previous = signal.signal(signal.SIGTERM, _interrupt)
        try:
            while True:
                try:
                    return process.wait(timeout=POLL_S)
                except subprocess.TimeoutExpired:
                    self.look()
        finally:
            signal.signal(signal.SIGTERM, previous)
            if process.poll() is None:  # interrupted: Snakemake cancels its jobs on SIGTERM
                process.terminate()
                process.wait()

    def look(self) -> None:
        try:
            queue = _run(["squeue", "--noheader", "--states=PENDING", "--format=%i|%P|%r|%Z|%k"])
        except subprocess.TimeoutExpired:
            return
        now = time.monotonic()
        for line in queue.stdout.splitlines():
            job, partition, reason, workdir, comment = (line.split("|") + [""] * 5)[:5]
            if Path(workdir) != self.folder or job in self.cancelled:
                continue
            why = self._never_starts(partition, reason, now)
            if why:
                _run(["scancel", job])
                self.cancelled[job] = f"{comment}: {why}"
                log.warning("slurm: job %s (%s) cancelled: %s", job, comment, why)

    def _never_starts(self, partition: str, reason: str, now: float) -> str | None:
        if reason in NEVER_STARTS:
            return f"it can never start in partition '{partition}' (reason {reason})"
        nodes = cluster_nodes(partition)
        if any(node.state in TAKING_JOBS for node in nodes):
            self._unusable_since.pop(partition, None)
            return None
        since = self._unusable_since.setdefault(partition, now)
        if now - since < self.grace_s:
            return None
        states = ", ".join(f"{node.name} {node.state}" for node in nodes) or "no nodes"
        return f"no node of partition '{partition}' has taken jobs for {self.grace_s:.0f} s ({states})"
