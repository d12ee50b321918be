# Export: the room as a mesh and a point cloud at chosen object states (docs/export.md), with each object's
# part alone when the scene has masks; the report shows sizes, timings and a thumbnail per state.


rule export:
    input:
        unpack(dataset_input),
        run=R("{scene}", "runs", "{method}", "run.json"),
    output:
        directory(R("{scene}", "export", "{method}")),
    log:
        R("{scene}", "logs", "export_{method}.log"),
    benchmark:
        R("{scene}", "benchmarks", "export_{method}.tsv")
    params:
        cli=LIVESCENE,
        run=run_folder,
        args=export_args,
        device=config["device"],
    threads: 2
    resources:
        mem_mb=6000,
        runtime=30,
        gpu=config["gpus"],
    conda:
        ENV
    shell:
        "{params.cli} export --run {params.run:q} --data {input.data:q} {params.args} --out {output:q}"
        " --device {params.device} --no-progress > {log:q} 2>&1"
