"""One render's iterations over many machines: prepare -> K shards -> merge (and the stages after it).

Started by `python -m pipeline run CONFIG --shards K --profile slurm` (pipeline/shards.py), which writes
runs/<name>/.workflow/shards.yaml and passes it as --configfile with that folder as working directory.
Every path in it is absolute, so jobs find their files on any node of a shared file system.
"""
from snakemake.exceptions import WorkflowError

if "shards" not in config:
    raise WorkflowError("run this workflow through `python -m pipeline run CONFIG --shards K --profile ...`")

SHARDS = int(config["shards"])
RUN = [config["python"], "-m", "pipeline"]
SETS = " ".join(f"--set {s!r}" for s in config["overrides"])
SHARD_DONE = f"{config['shards_dir']}/shard-{{index}}/shard.json"

wildcard_constraints:
    index=r"\d+",

localrules: all, prepare


rule all:
    default_target: True
    input:
        config["done"],


rule prepare:
    output:
        config["prepared"],
    log:
        f"{config['folder']}/logs/prepare.log",
    params:
        stages=" ".join(f"--stage {s}" for s in config["prepare_stages"]),
    shell:
        "cd {config[workdir]:q} && {config[python]:q} -m pipeline run {config[config]:q} {SETS} --quiet"
        " {params.stages} > {log:q} 2>&1"


rule shard:
    input:
        rules.prepare.output,
    output:
        SHARD_DONE,
    log:
        f"{config['folder']}/logs/shard-{{index}}.log",
    threads: config["threads"]
    resources:  # SHARD_RESOURCES in pipeline/shards.py, where the SLURM checks read them too
        mem_mb=config["resources"]["shard"]["mem_mb"],
        runtime=config["resources"]["shard"]["runtime"],
    shell:
        "cd {config[workdir]:q} && {config[python]:q} -m pipeline shard {config[config]:q} {SETS} --quiet"
        " --index {wildcards.index} --shards {SHARDS} --set threads={threads} > {log:q} 2>&1"


rule merge:
    input:
        expand(SHARD_DONE, index=range(SHARDS)),
    output:
        config["done"],
    log:
        f"{config['folder']}/logs/merge.log",
    threads: config["threads"]
    shell:
        "cd {config[workdir]:q} && {config[python]:q} -m pipeline run {config[config]:q} {SETS} --quiet"
        " --shards {SHARDS} --set threads={threads} > {log:q} 2>&1"
