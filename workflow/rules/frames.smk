# Frames: extract the frames of a video or image folder (left out when poses come with the data).


rule frames:
    input:
        unpack(frames_input),
    output:
        directory(R("{scene}", "frames")),
    log:
        log_path("frames"),
    benchmark:
        bench_path("frames")
    params:
        cli=LIVESCENE,
        video=frames_video,
        select=frames_selection,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=20,
    conda:
        ENV
    shell:
        "{params.cli} frames --video {params.video:q} --out {output:q}{params.select} --no-progress > {log:q} 2>&1"
