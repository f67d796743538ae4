"""Cutting load with real cutter–workpiece engagement (Z-map stock).

* :mod:`.stock` — batched Z-map height field of the workpiece block;
* :mod:`.engagement` — angle convention, near-field swept path, tooth depth;
* :mod:`.force` — chip thickness and mechanistic tooth forces (Eq. 10-13);
* :mod:`.kernel` — one communication step: substeps, exact means, entry/exit location, peak;
* :mod:`.component` — :class:`CuttingLoad`, the FMI-style component;
* :mod:`.tool_table` — the tool table (the cutter of each tool number of a program with several tools);
* :mod:`.effects`, :mod:`.chip`, :mod:`.effect_model` — effect terms (runout, helix, edge force, deflection,
  wear, spindle droop, chatter), off by default; :mod:`.kernel_effects` and :mod:`.path_effects` the steps
  with them on (Z-map and path mode);
* :mod:`.study` — Z-map resolution study (accuracy and cost).
"""
from .component import CuttingError, CuttingLoad
from .engagement import NearField, SweptPath, periphery_points, tooth_depth
from .force import average_forces_on_tool, chip_thickness, paper_matrix, tooth_forces_on_tool
from .kernel import StepResult, cut_step
from .stock import StockError, ZMapStock, disc_sweep_cover, round_down_f32

__all__ = [
    "CuttingError", "CuttingLoad", "NearField", "StepResult", "StockError", "SweptPath", "ZMapStock",
    "average_forces_on_tool", "cut_step", "chip_thickness", "disc_sweep_cover", "paper_matrix", "periphery_points",
    "round_down_f32", "tooth_depth", "tooth_forces_on_tool",
]
