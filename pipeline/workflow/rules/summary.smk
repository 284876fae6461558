# The sweep summary: the table (CSV, Markdown, HTML), the poster grid, the error-against-time plot
# and report.html, from every point's stage outputs. It is light, so it runs where Snakemake runs.

rule summary:
    input:
        done=expand(POINT_DONE, point=POINTS),
        configs=expand(POINT_CONFIG, point=POINTS),
        workflow=f"{FOLDER}/workflow.yaml",
    output:
        csv=f"{FOLDER}/summary.csv",
        md=f"{FOLDER}/summary.md",
        html=f"{FOLDER}/summary.html",
        poster=f"{FOLDER}/poster.png",
        report=f"{FOLDER}/report.html",
    log:
        f"{FOLDER}/logs/summary.log",
    threads: 1
    params:
        workdir=WORKDIR,
        python=PYTHON,
    shell:
        "cd {params.workdir:q} && {params.python:q} -m pipeline.sweep {input.workflow:q} > {log:q} 2>&1"
