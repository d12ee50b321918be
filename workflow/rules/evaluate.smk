# Evaluate: held-out metrics and renders of every trained run; with truth also unseen state
# combinations (and the pose alignment when the poses were estimated); grounding with names.


rule evaluate:
    input:
        unpack(evaluate_input),
    output:
        report(
            directory(R("{scene}", "eval", "{method}")),
            patterns=["{name}.png"],
            caption="../report/evaluate.rst",
            category="Held-out renders",
            subcategory="{method}",
            labels={"scene": "{scene}", "method": "{method}", "view": "{name}"},
        ),
    log:
        R("{scene}", "logs", "evaluate_{method}.log"),
    benchmark:
        R("{scene}", "benchmarks", "evaluate_{method}.tsv")
    params:
        cli=LIVESCENE,
        args=evaluate_args,
        run=run_folder,
        views=config["evaluate"]["max_views"],
        unseen=config["evaluate"]["unseen_views"],
        max_unseen=config["evaluate"]["max_unseen_renders"],
        max_pairs=config["evaluate"]["max_locality_pairs"],
        max_side=config["evaluate"]["max_side"],
        device=config["device"],
        settings=named(views=config["evaluate"]["max_views"], unseen=config["evaluate"]["unseen_views"],
                       max_unseen=config["evaluate"]["max_unseen_renders"],
                       max_pairs=config["evaluate"]["max_locality_pairs"], max_side=config["evaluate"]["max_side"],
                       device=config["device"]),
    threads: 2
    resources:
        mem_mb=6000,
        runtime=60,
        gpu=config["gpus"],
    conda:
        ENV
    shell:
        "{params.cli} evaluate --run {params.run:q} --data {input.data:q} {params.args} --out {output:q}"
        " --max-views {params.views} --unseen-views {params.unseen} --max-unseen-renders {params.max_unseen}"
        " --max-locality-pairs {params.max_pairs} --max-side {params.max_side} --device {params.device}"
        " --no-progress > {log:q} 2>&1"
