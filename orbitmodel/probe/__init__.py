"""Stage II: the physics probe that reads states out of the world model's imagined latents.

``integrator`` (batched rigid-body kinematics), ``model`` (:class:`PhysicsProbe`), ``baselines``
(the state-only MLP and constant velocity), ``train`` (``orbitmodel probe``), ``evaluate`` and
``figures`` (``orbitmodel eval probe``: the paper's Table I and Figure 5).
"""

from orbitmodel.probe.model import PhysicsProbe

__all__ = ["PhysicsProbe"]
