# Labels: ingest the scene's masks (PNG id maps, npy, COCO, LabelMe) as canonical LiveScene masks.


rule labels:
    input:
        unpack(labels_input),
    output:
        directory(R("{scene}", "labels")),
    log:
        log_path("labels"),
    benchmark:
        bench_path("labels")
    params:
        cli=LIVESCENE,
        args=labels_args,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    shell:
        "{params.cli} labels {params.args} --frames {input.frames:q} --out {output:q} --no-progress > {log:q} 2>&1"
