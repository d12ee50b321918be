# Poses: COLMAP structure from motion on the frames, interactive objects masked out; and, when the
# scene has truth, the error of the estimated poses against it.

NO_ORIENT = "" if config["poses"]["orient"] else " --no-orient"  # in the command only when set: unchanged jobs


rule poses:
    wildcard_constraints:
        scene=scene_pattern(lambda s: not imported_model(s)),  # poses_import writes the same folder
    input:
        unpack(poses_input),
    output:
        directory(R("{scene}", "poses")),
    log:
        log_path("poses"),
    benchmark:
        bench_path("poses")
    params:
        cli=LIVESCENE,
        masks=poses_args,  # the masks, and the sheet's camera column when set
        seed=config["seed"],
        matcher=config["poses"]["matcher"],
        features=config["poses"]["max_features"],
        settings=named(seed=config["seed"], matcher=config["poses"]["matcher"],
                       features=config["poses"]["max_features"]),
    # COLMAP runs on one thread here (its default, docs/poses.md "Repeatability": more threads give other poses each
    # run), so the rule takes one core: with two it waited for both to be free, behind every one-core training and
    # evaluation of a sheet, and left one idle
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    conda:
        ENV
    shell:
        "{params.cli} poses --frames {input.frames:q} --out {output:q} {params.masks} --threads {threads}"
        " --seed {params.seed} --matcher {params.matcher} --max-features {params.features}"
        f"{NO_ORIENT} --no-progress > {{log:q}} 2>&1"


rule poses_import:
    wildcard_constraints:
        scene=scene_pattern(imported_model),
    input:
        frames=R("{scene}", "frames"),
        model=lambda w: imported_model(w.scene),
        model_files=lambda w: folder_files(imported_model(w.scene)),
    output:
        directory(R("{scene}", "poses")),
    log:
        log_path("poses_import"),
    benchmark:
        bench_path("poses_import")
    params:
        cli=LIVESCENE,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    shell:
        "{params.cli} poses import --model {input.model:q} --frames {input.frames:q} --out {output:q}"
        f"{NO_ORIENT} > {{log:q}} 2>&1"


rule pose_compare:
    input:
        poses=R("{scene}", "poses"),
        truth=lambda w: truth_dir(w.scene),
    output:
        report(
            R("{scene}", "pose_error.json"),
            caption="../report/pose_error.rst",
            category="Poses",
            labels={"scene": "{scene}", "file": "pose error vs truth"},
        ),
    log:
        log_path("pose_compare"),
    benchmark:
        bench_path("pose_compare")
    params:
        cli=LIVESCENE,
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        ENV
    shell:
        "{params.cli} poses compare --pred {input.poses:q}/transforms.json --truth {input.truth:q}/truth/transforms.json"
        " --out {output:q} > {log:q} 2>&1"
