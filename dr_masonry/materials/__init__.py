"""Material parameter sets: the joint law of the contacts and the plastic-damage law of the blocks."""
from .joint import JointLaw
from .plastic_damage import PlasticDamage

__all__ = ["JointLaw", "PlasticDamage"]
