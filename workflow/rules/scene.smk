# Scene dataset: assemble frames, poses, labels and states into the dataset contract (the dataset
# stage, `livescene dataset assemble`), or check a ready dataset against it (`livescene scene`) and copy it
# into the upright world (`livescene dataset orient`); measure its frames' exposure once for every method
# (`livescene scene exposure`).


rule assemble:
    wildcard_constraints:
        scene=scene_pattern(from_frames),  # dataset_orient writes the same folder for ready datasets
    input:
        unpack(assemble_input),
    output:
        directory(R("{scene}", "dataset")),
    log:
        log_path("assemble"),
    benchmark:
        bench_path("assemble")
    params:
        cli=LIVESCENE,
        args=assemble_args,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    shell:
        "{params.cli} dataset assemble --frames {input.frames:q} --poses {input.poses:q} {params.args} --out {output:q}"
        " --no-progress > {log:q} 2>&1"


rule scene_validate:
    input:
        data=lambda w: row(w.scene)["path"],
        data_files=lambda w: folder_files(row(w.scene)["path"]),
    output:
        R("{scene}", "dataset_valid.json"),
    log:
        log_path("scene_validate"),
    benchmark:
        bench_path("scene_validate")
    params:
        cli=LIVESCENE,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    shell:
        "({params.cli} scene validate {input.data:q} && {params.cli} scene info {input.data:q} > {output:q})"
        " > {log:q} 2>&1"


rule dataset_orient:
    wildcard_constraints:
        scene=scene_pattern(orients_ready_dataset),
    input:
        data=lambda w: row(w.scene)["path"],
        data_files=lambda w: folder_files(row(w.scene)["path"]),
        valid=R("{scene}", "dataset_valid.json"),
    output:
        directory(R("{scene}", "dataset")),
    log:
        log_path("dataset_orient"),
    benchmark:
        bench_path("dataset_orient")
    params:
        cli=LIVESCENE,
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,  # minutes: without a point cloud, COLMAP triangulates on one core (~1 s per image)
    conda:
        ENV
    shell:
        "{params.cli} dataset orient --data {input.data:q} --out {output:q} > {log:q} 2>&1"


rule exposure:
    input:
        unpack(dataset_input),
    output:
        R("{scene}", "exposure.json"),
    log:
        log_path("exposure"),
    benchmark:
        bench_path("exposure")
    params:
        cli=LIVESCENE,
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,  # minutes: ~7 s for the demo's 120 frames, about a minute for a 300-frame phone video
    conda:
        ENV
    shell:
        "{params.cli} scene exposure {input.data:q} --out {output:q} > {log:q} 2>&1"
