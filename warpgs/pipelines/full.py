"""The full method's names where scripts imported them before it moved to ``warpgs.methods.full``."""

from warpgs.methods.full import (ABLATIONS, FullMethod, append_gaussians, check_settings, depth_prior,  # noqa: F401
                                 inputs_plane_sweep, phase_boundaries, pseudo_pair)
