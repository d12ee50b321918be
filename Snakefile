# Entry point for `snakemake --cores 2` at the repository root; the workflow lives in workflow/.
include: "workflow/Snakefile"


# Snakemake does not take the default target from an included file, so name it here.
rule default:
    default_target: True
    input:
        rules.all.input,
