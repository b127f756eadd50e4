"""The string model: numba kernels of the paper's equations of motion, their NumPy reference,
the parameter sets of Table 2 and eq. (2), and the rest state (docs/string_model.md).
"""
from .parameters import decode, ensemble_parameters, first_parameters, planned_parameters, start_chi
from .rest_state import FOLD_CHORD_SHARE, fill_rest_pose, folded_points
from .hanging import hanging_equilibrium, straight_hanging
from .string_model import closest_approach_batch, simulate, simulate_batch

__all__ = ["FOLD_CHORD_SHARE", "closest_approach_batch", "decode", "ensemble_parameters", "fill_rest_pose", "folded_points", "first_parameters", "hanging_equilibrium", "planned_parameters", "simulate", "simulate_batch", "start_chi", "straight_hanging"]
