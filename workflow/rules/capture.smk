# Synthetic captures: render the spec (video, masks, key frames, names, truth), and, when the
# scene's poses are "given", a scene dataset straight from the truth.


rule capture:
    input:
        spec=lambda w: row(w.scene)["path"],
    output:
        directory(R("{scene}", "capture")),
    log:
        log_path("capture"),
    benchmark:
        bench_path("capture")
    params:
        cli=LIVESCENE,
        seed=config["seed"],
    threads: 1
    resources:
        mem_mb=2000,
        runtime=20,
    conda:
        ENV
    shell:
        "{params.cli} capture --spec {input.spec:q} --out {output:q} --seed {params.seed} --no-progress > {log:q} 2>&1"


rule capture_dataset:
    input:
        R("{scene}", "capture"),
    output:
        directory(R("{scene}", "truth_dataset")),
    log:
        log_path("capture_dataset"),
    benchmark:
        bench_path("capture_dataset")
    params:
        cli=LIVESCENE,
        args=capture_dataset_args,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    shell:
        "{params.cli} capture dataset --capture {input:q} --out {output:q} {params.args} --no-progress > {log:q} 2>&1"
