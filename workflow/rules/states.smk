# States: interpolate the sparse key-frame states to every extracted frame.


rule states:
    input:
        unpack(states_input),
    output:
        directory(R("{scene}", "states")),
    log:
        log_path("states"),
    benchmark:
        bench_path("states")
    params:
        cli=LIVESCENE,
        args=states_args,
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        ENV
    shell:
        "{params.cli} states {params.args} --frames {input.frames:q} --out {output:q} > {log:q} 2>&1"
