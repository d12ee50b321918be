"""Run the configured language commands through `livescene control` on one trained run.

Snakemake calls this with `script:`. Each command is one call of the control CLI's main() in this
process (so Python and torch load once); its JSON goes to commands.json and its render next to it.
"{object}" in a command expands to every object name of the dataset.
"""

import contextlib
import io
import json
import shutil
from pathlib import Path

import yaml

from stages.language.control_cli import main as control_main

smk = snakemake  # noqa: F821 (injected by Snakemake)
run_dir = str(Path(smk.input.run).parent)
out = Path(smk.output[0])
tmp = out.with_name(f".{out.name}.tmp")
shutil.rmtree(tmp, ignore_errors=True)
tmp.mkdir(parents=True)
mapping = yaml.safe_load(Path(smk.input.data, "mapping.yaml").read_text()) or {}
names = [str(mapping[k]) for k in sorted(mapping)]
commands = []
for template in smk.params.commands:
    commands += [template.replace("{object}", n) for n in names] if "{object}" in template else [template]

results = []
with open(smk.log[0], "w") as log:
    for i, command in enumerate(commands):
        image = f"command_{i:02d}.png"
        stdout, stderr = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            code = control_main(["--run", run_dir, "--data", smk.input.data, "--device", smk.params.device,
                                 "--out", str(tmp / image), command])
        log.write(f"$ livescene control {command!r} -> exit {code}\n{stderr.getvalue()}\n")
        if code == 0:
            result = json.loads(stdout.getvalue())
            result["image"] = str(out / image)
        else:
            lines = stderr.getvalue().strip().splitlines()
            result = {"command": command, "error": lines[-1] if lines else f"exit status {code}"}
        results.append(result)

(tmp / "commands.json").write_text(json.dumps({"run": run_dir, "commands": results}, indent=2))
shutil.rmtree(out, ignore_errors=True)
tmp.rename(out)
