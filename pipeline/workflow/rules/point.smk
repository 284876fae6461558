# One job per sweep point. Snakemake re-runs a point when its resolved config is newer than its
# last stage's manifest (pipeline/sweep.py rewrites the config only when its content changes); the
# stage runner then skips every stage whose manifest still matches.

rule point:
    input:
        config=POINT_CONFIG,
    output:
        done=POINT_DONE,
    log:
        f"{FOLDER}/logs/{{point}}.log",
    # The C++ core gets exactly the threads Snakemake grants (`--set threads`); set-threads in a
    # profile overrides the sweep's `threads`, and --cores below it scales it down.
    threads: config["threads"]
    resources:  # POINT_RESOURCES in pipeline/sweep.py, where the SLURM checks read them too
        mem_mb=config["resources"]["point"]["mem_mb"],
        runtime=config["resources"]["point"]["runtime"],
    params:
        workdir=WORKDIR,
        python=PYTHON,
    shell:
        "cd {params.workdir:q} && {params.python:q} -m pipeline run {input.config:q} --quiet"
        " --set threads={threads} > {log:q} 2>&1"
