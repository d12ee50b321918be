"""The dataset stage: join the frames, poses, labels and states stages' folders into one scene dataset.

It comes after those stages and reads their outputs (docs/data-contract.md, "Stage order"); the dataset
it writes follows the contract of ``stages.scene``, which every stage shares.
"""

from .assemble import AssembleConfig, AssembleError, assemble_scene

__all__ = ["AssembleConfig", "AssembleError", "assemble_scene"]
