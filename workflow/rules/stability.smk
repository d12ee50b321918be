# Stability: the numerical-stability / guard / bad-input suite, once for all scenes.
# The checks ship in the livescene package (docs/stability.md). The one that dry-runs the workflow with a
# broken config copies the checkout named by --workflow: this workflow's own, the folder holding Snakefile,
# workflow/ and config/ (two levels above this file). It is given relative to the working directory the
# jobs run in ("." by default), so that a moved or cloned checkout changes no params and reruns nothing.
STABILITY_WORKFLOW = os.path.relpath(Path(workflow.current_basedir).parents[1])


rule stability:
    output:
        str(Path(RESULTS, "stability", "summary.json")),
    log:
        str(Path(RESULTS, "stability", "stability.log")),
    benchmark:
        str(Path(RESULTS, "stability", "benchmark.tsv"))
    params:
        cli=LIVESCENE,
        args=" ".join(
            (["--quick"] if config["stability"]["quick"] else [])
            + [f"--group {g}" for g in config["stability"]["groups"]]
        ),
        workflow=STABILITY_WORKFLOW,
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    conda:
        ENV
    shell:
        # Exit status 1 means a case failed: that is a finding for the report, not a broken job.
        "{params.cli} stability {params.args} --workflow {params.workflow:q} --threads {threads} --out {output:q}"
        " > {log:q} 2>&1 || test -s {output:q}"
