# Model: train LiveScene and the baselines listed for the scene, every method for the same number of steps
# (a wall-clock budget only when config train.max_seconds asks for one).


rule train:
    input:
        unpack(train_input),
    output:
        # run.json, not the folder: an interrupted job leaves its checkpoints and the rerun resumes (a job rerun
        # for new inputs or config finds them stale and starts over: --restart-stale).
        R("{scene}", "runs", "{method}", "run.json"),
    log:
        R("{scene}", "logs", "train_{method}.log"),
    benchmark:
        R("{scene}", "benchmarks", "train_{method}.tsv")
    params:
        cli=LIVESCENE,
        args=train_args,
        run=lambda w, output: str(Path(output[0]).parent),
        preset=config["preset"],
        steps=config["train"]["steps"],
        seconds=config["train"]["max_seconds"],
        eval_every=config["train"]["eval_every"],
        seed=config["seed"],
        device=config["device"],
        # the configured count, not {threads}: Snakemake scales that down to --cores, and torch's reductions (so the
        # weights) depend on the thread count
        torch_threads=config["train"]["threads"],
        settings=named(preset=config["preset"], steps=config["train"]["steps"],
                       seconds=config["train"]["max_seconds"], eval_every=config["train"]["eval_every"],
                       seed=config["seed"], device=config["device"], threads=config["train"]["threads"]),
    threads: config["train"]["threads"]
    # a free core goes to a waiting training before an evaluation or export: every method's evaluation waits for
    # its training, so the last training finishing early shortens the job (docs/workflow.md, "Machines")
    priority: 1
    resources:
        mem_mb=8000,
        # minutes: a cpu-demo step takes ~0.1 s on 2 cores; a time budget caps it
        runtime=int(min(config["train"]["steps"] * 0.5, config["train"]["max_seconds"] or 1e9) / 60) + 15,
        gpu=config["gpus"],
    conda:
        ENV
    shell:
        "{params.cli} train --data {input.data:q} --method {wildcards.method} --preset {params.preset}"
        " --out {params.run:q} --resume --restart-stale --max-steps {params.steps} --max-seconds {params.seconds} --seed {params.seed} --device {params.device}"
        " --set train.threads={params.torch_threads} --set train.eval_every={params.eval_every} {params.args} --no-progress > {log:q} 2>&1"
