"""Fields: what a point looks like (density, colour), which object drives it, its state, its language."""

from .density_field import DensityField
from .language_table import LanguageTable
from .probability_field import ProbabilityField
from .radiance_field import RadianceField
from .state_field import StateField

__all__ = ["DensityField", "LanguageTable", "ProbabilityField", "RadianceField", "StateField"]
