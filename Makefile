# The two commands of the README. Each bootstraps .venv when it is missing or stale.
.PHONY: run test lint clean-results

run:
	@scripts/bootstrap.sh
	.venv/bin/snakemake --cores 2 --workflow-profile workflow/profiles/default

test:
	@scripts/bootstrap.sh --test
	.venv/bin/ruff check .
	.venv/bin/python -m pytest -q

lint:
	.venv/bin/ruff check . && .venv/bin/snakemake --lint

clean-results:
	rm -rf results reports/*.html reports/scenes
