# Stability: the numerical-stability / guard / bad-input suite, once for all scenes.


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
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    conda:
        ENV
    shell:
        # Exit status 1 means a case failed: that is a finding for the report, not a broken job.
        "{params.cli} stability {params.args} --threads {threads} --out {output} > {log} 2>&1"
        " || test -s {output}"
