"""The virtual lab's second physics: the string as a PyElastica Cosserat rod (draft)."""
from .material import RodMaterial, rod_material
from .sim import RodSim, simulate_rod

__all__ = ["RodMaterial", "RodSim", "rod_material", "simulate_rod"]
