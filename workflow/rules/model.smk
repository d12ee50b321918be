# Model: train LiveScene and the baselines listed for the scene, within a wall-clock budget.


rule train:
    input:
        unpack(train_input),
    output:
        directory(R("{scene}", "runs", "{method}")),
    log:
        R("{scene}", "logs", "train_{method}.log"),
    benchmark:
        R("{scene}", "benchmarks", "train_{method}.tsv")
    params:
        cli=LIVESCENE,
        args=train_args,
        preset=config["preset"],
        seconds=config["train"]["max_seconds"],
        seed=config["seed"],
        device=config["device"],
    threads: 2
    resources:
        mem_mb=8000,
        runtime=int(config["train"]["max_seconds"] / 60) + 15,
        gpu=config["gpus"],
    conda:
        ENV
    shell:
        "{params.cli} train --data {input.data} --method {wildcards.method} --preset {params.preset}"
        " --out {output} --max-seconds {params.seconds} --seed {params.seed} --device {params.device}"
        " --set train.threads={threads} {params.args} --no-progress > {log} 2>&1"
