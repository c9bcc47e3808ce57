"""parallax: self-trainable depth perception from eye pursuit and motion parallax.

Implements and extends Prucksakorn, Jeong & Chong, "A Self-Trainable Depth Perception
Method from Eye Pursuit and Motion Parallax" (``../shared/paper.md``). One sub-package per
box of the paper's architecture (Fig. 1): ``envs`` (the world), ``coding`` (§3.3),
``policy`` (§3.4) and ``distance`` (§3.5); ``train`` wires them together.
"""

__version__ = "0.1.0"
