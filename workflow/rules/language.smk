# Language: the language-table targets of a scene with object names, and the language commands
# run on a trained model (left out when the scene has no names).


rule language_targets:
    input:
        unpack(dataset_input),
    output:
        R("{scene}", "language", "targets.npz"),
    log:
        log_path("language_targets"),
    benchmark:
        bench_path("language_targets")
    params:
        cli=LIVESCENE,
    threads: 1
    resources:
        mem_mb=3000,
        runtime=10,
    conda:
        ENV
    shell:
        "{params.cli} language targets --data {input.data:q} --out {output:q} > {log:q} 2>&1"


rule control:
    input:
        unpack(dataset_input),
        run=R("{scene}", "runs", "{method}", "run.json"),
    output:
        directory(R("{scene}", "control", "{method}")),
    log:
        R("{scene}", "logs", "control_{method}.log"),
    benchmark:
        R("{scene}", "benchmarks", "control_{method}.tsv")
    params:
        commands=control_commands,
        device=config["device"],
    threads: 1
    resources:
        mem_mb=4000,
        runtime=20,
        gpu=config["gpus"],
    conda:
        ENV
    script:
        "../scripts/control_commands.py"
