# Config and scene-sheet loading, schema validation and the input functions
# that decide per scene which rules it needs.
import pandas as pd
from snakemake.utils import validate


validate(config, schema="../schemas/config.schema.yaml")

scenes = (
    pd.read_csv(config["scenes"], sep="\t", dtype=str, comment="#")
    .fillna("")
    .set_index("scene", drop=False)
)
validate(scenes, schema="../schemas/scenes.schema.yaml")


def all_targets():
    """Final outputs of every scene; grows as stages are wired in."""
    return []
