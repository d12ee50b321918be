# Report: state sweeps for the sliders, one self-contained HTML page per scene, and the index.


rule sweep:
    input:
        unpack(dataset_input),
        run=R("{scene}", "runs", "{method}", "run.json"),
    output:
        directory(R("{scene}", "sweep", "{method}")),
    log:
        R("{scene}", "logs", "sweep_{method}.log"),
    benchmark:
        R("{scene}", "benchmarks", "sweep_{method}.tsv")
    params:
        cli=LIVESCENE,
        run=run_folder,
        steps=config["report"]["sweep_steps"],
        scale=config["report"]["sweep_scale"],
        device=config["device"],
        settings=named(steps=config["report"]["sweep_steps"], scale=config["report"]["sweep_scale"],
                       device=config["device"]),
    threads: 2
    resources:
        mem_mb=4000,
        runtime=30,
        gpu=config["gpus"],
    conda:
        ENV
    shell:
        "{params.cli} report sweep --run {params.run:q} --data {input.data:q} --out {output:q} --steps {params.steps}"
        " --scale {params.scale} --device {params.device} > {log:q} 2>&1"


rule report_scene:
    input:
        unpack(report_scene_input),
    output:
        page=report(
            str(Path(REPORTS, "scenes", "{scene}.html")),
            caption="../report/scene_page.rst",
            category="HTML report",
            labels={"page": "{scene}"},
        ),
        summary=R("{scene}", "report", "summary.json"),
        # The page reads only what this manifest names (role -> path, from the inputs above).
        inputs=R("{scene}", "report", "inputs.json"),
    log:
        log_path("report"),
    benchmark:
        bench_path("report")
    params:
        cli=LIVESCENE,
        manifest=report_manifest,
        plan=lambda w: json.dumps({k: {"needed": v[0], "why": v[1]} for k, v in plan(w.scene).items()}),
        methods=lambda w: ",".join(methods(w.scene)),
        index=str(Path(REPORTS, "index.html")),
        views=config["report"]["grid_views"],
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    shell:
        "printf '%s\\n' {params.manifest:q} > {output.inputs:q}"
        " && {params.cli} report scene --scene {wildcards.scene} --inputs {output.inputs:q}"
        " --methods {params.methods} --plan-json {params.plan:q} --views {params.views}"
        " --out {output.page:q} --index {params.index:q} --summary {output.summary:q} > {log:q} 2>&1"


rule report_index:
    input:
        summaries=expand(R("{scene}", "report", "summary.json"), scene=SELECTED),
        pages=expand(str(Path(REPORTS, "scenes", "{scene}.html")), scene=SELECTED),
    output:
        index=report(
            str(Path(REPORTS, "index.html")),
            caption="../report/index_page.rst",
            category="HTML report",
            labels={"page": "index"},
        ),
        csv=report(
            str(Path(REPORTS, "verdicts.csv")),
            caption="../report/verdicts.rst",
            category="HTML report",
            labels={"page": "verdicts"},
        ),
        # per scene and stage, the SHA-256 of the stage's result files: diff two machines' to see where they part
        digests=report(
            str(Path(REPORTS, "digests.csv")),
            caption="../report/digests.rst",
            category="HTML report",
            labels={"page": "digests"},
        ),
    log:
        str(Path(RESULTS, "logs", "report_index.log")),
    benchmark:
        str(Path(RESULTS, "benchmarks", "report_index.tsv"))
    params:
        cli=LIVESCENE,
        # Pages of the sheet's other scenes made by earlier runs (`--config only=...`) are listed apart.
        earlier=lambda w: earlier_arg(),
        pending=lambda w: pending_arg(),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        ENV
    shell:
        "{params.cli} report index --summaries {input.summaries:q} {params.earlier} {params.pending}"
        " --out {output.index:q} --csv {output.csv:q} --digests {output.digests:q} > {log:q} 2>&1"

