"""The FEM core: W soft objects (tetrahedral, fixed-corotated, backward Euler) with kinematic pad
boxes and the ground, batched in flat arrays, in NVIDIA Warp (CPU and CUDA).

Public API (Newton's Model/State/Control split)::

    from defgrasp_env.sim import (ContactParams, Control, ImplicitSolver, Material, SolverConfig,
                                  State, build_model, make_object_mesh)

    mesh = make_object_mesh("sphere")
    model = build_model([mesh], [Material(youngs_modulus=1e5)], pad_half_extents=[(0.008, 0.019, 0.011)])
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, SolverConfig())
    stats = solver.step(state, state, control, dt=0.05)   # SolveStats: per-world convergence report

``solver.advance(state_in, state_out, control, dt)`` is ``step`` without the report's download
(``state_in`` is only read when distinct from ``state_out``; ``full_outputs=False`` writes only
the contact outputs, for a caller's intermediate substeps); ``SolveReport.fold`` accumulates the
reports of several solves on the device for one download.

``meshing`` builds tet meshes (named objects, watertight surfaces); ``pad_motion`` sizes substeps
to the pads' travel.
"""

from . import meshing
from .materials import Material
from .meshing import OBJECT_SHAPES, TetMesh, make_object_mesh, mesh_from_surface
from .model import ContactParams, Model, build_model, set_world_material
from .pad_motion import MAX_PAD_TRAVEL, max_pad_travel, substeps_for_travel
from .solve_report import SolveReport
from .solver import ImplicitSolver, SolverConfig, SolveStats
from .solver_launches import SubstepLaunches
from .solver_scratch import SolverScratch
from .state import Control, State

__all__ = [
    "ContactParams", "Control", "ImplicitSolver", "MAX_PAD_TRAVEL", "Material", "Model", "OBJECT_SHAPES",
    "SolveReport", "SolveStats", "SolverConfig", "SolverScratch", "State", "SubstepLaunches", "TetMesh", "build_model",
    "max_pad_travel", "make_object_mesh", "mesh_from_surface", "meshing", "set_world_material",
    "substeps_for_travel",
]
