"""MotionLab: editing motion capture by signal processing (seed 002, Bruderlin & Williams).

Pure functions over an immutable :class:`Motion` (each returns a new Motion):

==========================  ==========================================================
``equalize``                multiresolution filter bank, gains per band (equalizer.py)
``displace``                displacement map: spline through key offsets (displacement.py)
``apply_layers``/``Layer``  additive "overAnimate" layers (displacement.py)
``reorient``                rotate/move the whole motion about the vertical (align.py)
``to_y_up``                 convert Z-up data (align.py)
``blend``                   N clips with offsets/scales, blend curve, auto-align (blend.py)
``change_speed``            speed curve → time warp (timewarp.py)
``make_cycle``/``best_loop``  seamless loops with offset (cycle.py)
``quality_report``          angular rates, Euler wraps, foot skate (quality.py)
==========================  ==========================================================
"""

from biomorph.motion.align import reorient, to_y_up, transform_root
from biomorph.motion.blend import blend
from biomorph.motion.cycle import best_loop, make_cycle
from biomorph.motion.displacement import Layer, apply_layers, displace, remove_layer
from biomorph.motion.equalizer import bands, equalize, n_bands
from biomorph.motion.motion import Motion, concatenate, guess_up_axis, preview_positions
from biomorph.motion.quality import quality_report
from biomorph.motion.timewarp import change_speed

__all__ = ["Motion", "concatenate", "guess_up_axis", "preview_positions", "equalize", "bands",
           "n_bands", "displace", "Layer", "apply_layers", "remove_layer", "reorient",
           "to_y_up", "transform_root", "blend", "change_speed", "make_cycle", "best_loop",
           "quality_report"]
