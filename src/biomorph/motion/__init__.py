"""MotionLab: editing motion capture by signal processing (seed 002)."""

from biomorph.motion.motion import Motion, concatenate, guess_up_axis, preview_positions

__all__ = ["Motion", "concatenate", "guess_up_axis", "preview_positions"]
